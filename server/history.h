// The undo and redo lists of a session (service.proto Undo, Redo). Each
// entry is the solid's exact state to go back to (solid::Solid::SaveState)
// and the scene that state belongs to (topology edits make new scenes), so
// undo and redo restore the solid bit for bit; the clock goes on.
//
// Bounded by bytes (server --undo_bytes): pushing past the limit drops the
// oldest undo entries first (then the oldest redo entries). Deterministic:
// the same pushes give the same lists, which is what lets the journal
// replay undo and redo after a crash.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include "dynsolid/journal.pb.h"
#include "dynsolid/scene.pb.h"
#include "solver/solid/saved_state.h"

namespace dynsolid::server {

struct HistoryItem {
  // solid::Solid::SaveStateParts(): entries saved while the material was
  // unchanged share its samples.
  solid::SavedState state;
  std::shared_ptr<const Scene> scene;  // the scene of that state
  std::string what;                    // "client C seq N: extrude"
  int64_t bytes() const;
};

class History {
 public:
  explicit History(int64_t limit_bytes) : limit_(limit_bytes) {}

  // A new undoable command was applied: `before` goes onto the undo list
  // and the redo list is cleared.
  void Record(HistoryItem before);
  bool can_undo() const { return !undo_.empty(); }
  bool can_redo() const { return !redo_.empty(); }
  // Undo: takes the newest undo entry and keeps `now` (the state being
  // left) as the newest redo entry. Redo: the other way round.
  HistoryItem Undo(HistoryItem now);
  HistoryItem Redo(HistoryItem now);
  // Peek at what Undo / Redo would return.
  const HistoryItem& next_undo() const { return undo_.back(); }
  const HistoryItem& next_redo() const { return redo_.back(); }

  int32_t undo_depth() const { return static_cast<int32_t>(undo_.size()); }
  int32_t redo_depth() const { return static_cast<int32_t>(redo_.size()); }
  int64_t bytes() const { return bytes_; }
  int64_t limit_bytes() const { return limit_; }

  // Snapshots: entries with scene indices into `scenes` (-1: `original`);
  // `scene_index` gives (and adds) the index of a scene.
  template <typename SceneIndex>
  void SaveTo(persist::Snapshot* snapshot, SceneIndex scene_index) const {
    for (const HistoryItem& h : undo_) Save(h, snapshot->add_undo(), scene_index(h.scene));
    for (const HistoryItem& h : redo_) Save(h, snapshot->add_redo(), scene_index(h.scene));
  }
  // Replaces the lists from a snapshot; `scene_of(index)` resolves scenes.
  template <typename SceneOf>
  void RestoreFrom(const persist::Snapshot& snapshot, SceneOf scene_of) {
    undo_.clear();
    redo_.clear();
    bytes_ = 0;
    for (const persist::HistoryEntry& e : snapshot.undo()) Add(undo_, Load(e, scene_of(e.scene())));
    for (const persist::HistoryEntry& e : snapshot.redo()) Add(redo_, Load(e, scene_of(e.scene())));
  }

 private:
  static void Save(const HistoryItem& h, persist::HistoryEntry* e, int32_t scene);
  static HistoryItem Load(const persist::HistoryEntry& e, std::shared_ptr<const Scene> scene);
  void Add(std::deque<HistoryItem>& list, HistoryItem item);
  void Trim();

  const int64_t limit_;
  std::deque<HistoryItem> undo_, redo_;  // oldest first
  int64_t bytes_ = 0;
};

}  // namespace dynsolid::server
