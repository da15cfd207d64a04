// Undo that belongs to the person who acted (service.proto Undo, Redo,
// RevertToScene).
//
// Design:
//  - An entry is ONE action of ONE client (its client_id): a command, a
//    drag or curve from press to release, or a stroke (the client's
//    consecutive commands with the same non-zero Command.gesture). It
//    holds the changes the action made (journal.proto UndoChange), each
//    with what its inverse needs: a load's or pin's id and what it was, a
//    gravity before and after, a paint's material samples before and
//    after on the elements it changed (material_diff.h), an edit with the
//    scene before it, a revert's whole state.
//  - A client's undo takes its own newest entry in effect and applies the
//    inverse to the solid AS IT IS NOW (sim_core_undo.cc): positions and
//    velocities go on, everyone else's later work stays. Redo applies the
//    action again. A new action of a client clears that client's redo.
//  - Where the inverse cannot apply because someone else's later work
//    built on it (an edit after it changed the control mesh, a gravity
//    set since), the undo is refused, naming that work; nothing changes.
//    Where there is nothing left to take back (someone removed the load
//    since), the undo does nothing and its redo will do nothing either, so
//    undoing a lot and redoing it all leaves the design as it was.
//  - Drags and curves never come back: their entry releases a drag still
//    held; redo does not put it back.
//  - Ids: a load or pin put back gets a new id; aliases map the old ids to
//    the new ones for every entry that names them.
//  - Control meshes have ids (0: the scene's own) so a paint or an edit
//    knows whether the mesh it was made on is still the one in place.
//  - This class is the bookkeeping only (no solid): deterministic, saved
//    whole in snapshots (UndoHistoryState), bounded by bytes (--undo_bytes:
//    the oldest entries go first).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "dynsolid/journal.pb.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::server {

class UndoHistory {
 public:
  explicit UndoHistory(int64_t limit_bytes) : limit_(limit_bytes) {}

  // A new action of `client` (or a further command of its current
  // gesture): returns the entry to add its changes to. Clears the
  // client's redo list when it starts a new entry. `gesture` 0: a new
  // entry always.
  persist::UndoEntry* Begin(const std::string& client, uint64_t gesture);
  // Call after changing an entry Begin gave (its size may have changed):
  // trims the oldest entries beyond the byte limit.
  void Commit(int64_t serial);
  // The entry with a drag or curve `id` (resolved) not yet released, or null.
  persist::UndoEntry* FindHeldDrag(int64_t id);

  // The client's next entry to undo (newest in effect) or redo (oldest
  // undone), or null.
  persist::UndoEntry* NextUndo(const std::string& client);
  persist::UndoEntry* NextRedo(const std::string& client);
  // The entry done: moved to the redo list (undone) or back.
  void MarkUndone(persist::UndoEntry* e, bool undone, bool noop);

  // Ids given again: `id` (as entries name it) is now `now`.
  void Alias(int64_t id, int64_t now);
  int64_t Resolve(int64_t id) const;

  // Control meshes: the current one's id, a fresh id for a new mesh, and
  // what made the current one ("Bob's \"extrude face 3\"").
  int64_t mesh() const { return state_.mesh(); }
  const std::string& mesh_cause() const { return state_.mesh_cause(); }
  void SetMesh(int64_t id, std::string cause);
  int64_t NewMesh() {
    state_.set_next_mesh(state_.next_mesh() + 1);
    return state_.next_mesh();
  }

  // Depths over everyone (SessionStats) and for one client.
  int32_t undo_depth() const;
  int32_t redo_depth() const;
  int32_t undo_depth(const std::string& client) const;
  int32_t redo_depth(const std::string& client) const;
  int64_t bytes() const { return bytes_; }
  int64_t limit_bytes() const { return limit_; }

  // The listing (InspectReply.history).
  void Describe(HistoryInfo* out) const;

  const google::protobuf::RepeatedPtrField<persist::UndoEntry>& entries() const {
    return state_.entries();
  }

  void SaveTo(persist::UndoHistoryState* out) const;
  void RestoreFrom(const persist::UndoHistoryState& in);

  // "Alice" for a client id, for messages ("you" when it is `asking`).
  static std::string Who(const std::string& client, const std::string& asking);

 private:
  persist::UndoEntry* Find(int64_t serial);
  void Recount();
  void Trim();

  const int64_t limit_;
  persist::UndoHistoryState state_;  // entries ascending by serial
  std::map<int64_t, int64_t> sizes_;    // serial -> bytes
  std::map<int64_t, int64_t> aliases_;  // (state_.aliases stays empty)
  int64_t bytes_ = 0;
};

// Plain names of actions ("extrude face 85", "stiffness stroke, 12 dabs").
std::string ActionName(const Command& c);
// The name of a stroke of `dabs` paints whose first was `c`.
std::string StrokeName(const Command& c, int32_t dabs);

}  // namespace dynsolid::server
