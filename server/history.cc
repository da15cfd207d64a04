#include "server/history.h"

#include "solver/solid/solid.h"

#include <utility>

namespace dynsolid::server {

int64_t HistoryItem::bytes() const {
  // The scene is shared with the solid or other entries; count its state
  // and label (what a snapshot stores per entry).
  return state.bytes() + static_cast<int64_t>(what.size());
}

void History::Add(std::deque<HistoryItem>& list, HistoryItem item) {
  bytes_ += item.bytes();
  list.push_back(std::move(item));
}

void History::Trim() {
  while (bytes_ > limit_ && !undo_.empty()) {
    bytes_ -= undo_.front().bytes();
    undo_.pop_front();
  }
  while (bytes_ > limit_ && !redo_.empty()) {
    bytes_ -= redo_.front().bytes();
    redo_.pop_front();
  }
}

void History::Record(HistoryItem before) {
  for (const HistoryItem& h : redo_) bytes_ -= h.bytes();
  redo_.clear();
  Add(undo_, std::move(before));
  Trim();
}

HistoryItem History::Undo(HistoryItem now) {
  HistoryItem back = std::move(undo_.back());
  undo_.pop_back();
  bytes_ -= back.bytes();
  Add(redo_, std::move(now));
  Trim();
  return back;
}

HistoryItem History::Redo(HistoryItem now) {
  HistoryItem back = std::move(redo_.back());
  redo_.pop_back();
  bytes_ -= back.bytes();
  Add(undo_, std::move(now));
  Trim();
  return back;
}

void History::Save(const HistoryItem& h, persist::HistoryEntry* e, int32_t scene) {
  e->set_solid_state(solid::Solid::JoinState(h.state));
  e->set_scene(scene);
  e->set_what(h.what);
}

HistoryItem History::Load(const persist::HistoryEntry& e, std::shared_ptr<const Scene> scene) {
  solid::SavedState state;
  state.head = e.solid_state();  // a whole state: no shared section
  return HistoryItem{std::move(state), std::move(scene), e.what()};
}

}  // namespace dynsolid::server
