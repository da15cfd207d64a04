#include "server/history.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace dynsolid::server {
namespace {

template <typename Ids>
std::string IdList(const Ids& ids) {
  return absl::StrJoin(ids, ", ");
}

std::string Noun(const char* one, const char* many, int n) { return n == 1 ? one : many; }

}  // namespace

persist::UndoEntry* UndoHistory::Find(int64_t serial) {
  auto* entries = state_.mutable_entries();
  auto it = std::lower_bound(entries->begin(), entries->end(), serial,
                             [](const persist::UndoEntry& e, int64_t s) { return e.serial() < s; });
  return it != entries->end() && it->serial() == serial ? &*it : nullptr;
}

persist::UndoEntry* UndoHistory::Begin(const std::string& client, uint64_t gesture) {
  // The client's newest entry: continue its gesture.
  auto* entries = state_.mutable_entries();
  persist::UndoEntry* last = nullptr;
  for (int i = entries->size() - 1; i >= 0; --i) {
    if ((*entries)[i].client_id() == client) {
      last = &(*entries)[i];
      break;
    }
  }
  if (gesture != 0 && last != nullptr && !last->undone() && last->gesture() == gesture) {
    return last;
  }
  // A new action: the client's redo list goes.
  bool removed = false;
  for (int i = entries->size() - 1; i >= 0; --i) {
    if ((*entries)[i].client_id() == client && (*entries)[i].undone()) {
      entries->DeleteSubrange(i, 1);
      removed = true;
    }
  }
  if (removed) Recount();
  state_.set_next_serial(state_.next_serial() + 1);
  persist::UndoEntry* e = entries->Add();
  e->set_serial(state_.next_serial());
  e->set_client_id(client);
  e->set_gesture(gesture);
  return e;
}

void UndoHistory::Commit(int64_t serial) {
  persist::UndoEntry* e = Find(serial);
  if (e == nullptr) return;
  const int64_t n = static_cast<int64_t>(e->ByteSizeLong());
  int64_t& size = sizes_[serial];
  bytes_ += n - size;
  size = n;
  Trim();
}

void UndoHistory::Recount() {
  sizes_.clear();
  bytes_ = 0;
  for (const persist::UndoEntry& e : state_.entries()) {
    const int64_t n = static_cast<int64_t>(e.ByteSizeLong());
    sizes_[e.serial()] = n;
    bytes_ += n;
  }
}

void UndoHistory::Trim() {
  auto* entries = state_.mutable_entries();
  int drop = 0;
  // Keep the newest entry whatever its size.
  while (bytes_ > limit_ && drop + 1 < entries->size()) {
    const int64_t s = (*entries)[drop].serial();
    bytes_ -= sizes_[s];
    sizes_.erase(s);
    ++drop;
  }
  if (drop > 0) entries->DeleteSubrange(0, drop);
}

persist::UndoEntry* UndoHistory::FindHeldDrag(int64_t id) {
  auto* entries = state_.mutable_entries();
  for (int i = entries->size() - 1; i >= 0; --i) {
    persist::UndoEntry& e = (*entries)[i];
    for (persist::UndoChange& c : *e.mutable_changes()) {
      if (c.has_drag() && !c.drag().released() && Resolve(c.drag().id()) == id) return &e;
    }
  }
  return nullptr;
}

persist::UndoEntry* UndoHistory::NextUndo(const std::string& client) {
  auto* entries = state_.mutable_entries();
  for (int i = entries->size() - 1; i >= 0; --i) {
    persist::UndoEntry& e = (*entries)[i];
    if (e.client_id() == client && !e.undone()) return &e;
  }
  return nullptr;
}

persist::UndoEntry* UndoHistory::NextRedo(const std::string& client) {
  for (persist::UndoEntry& e : *state_.mutable_entries()) {
    if (e.client_id() == client && e.undone()) return &e;
  }
  return nullptr;
}

void UndoHistory::MarkUndone(persist::UndoEntry* e, bool undone, bool noop) {
  e->set_undone(undone);
  e->set_noop(noop);
  Commit(e->serial());
}

void UndoHistory::Alias(int64_t id, int64_t now) {
  if (id == now) {
    aliases_.erase(id);
    return;
  }
  aliases_[id] = now;
}

int64_t UndoHistory::Resolve(int64_t id) const {
  // Chains are short; a bound guards against a cycle.
  for (int k = 0; k < 64; ++k) {
    auto it = aliases_.find(id);
    if (it == aliases_.end() || it->second == id) return id;
    id = it->second;
  }
  return id;
}

void UndoHistory::SetMesh(int64_t id, std::string cause) {
  state_.set_mesh(id);
  state_.set_mesh_cause(std::move(cause));
}

int32_t UndoHistory::undo_depth() const {
  int32_t n = 0;
  for (const persist::UndoEntry& e : state_.entries()) n += !e.undone();
  return n;
}
int32_t UndoHistory::redo_depth() const {
  int32_t n = 0;
  for (const persist::UndoEntry& e : state_.entries()) n += e.undone();
  return n;
}
int32_t UndoHistory::undo_depth(const std::string& client) const {
  int32_t n = 0;
  for (const persist::UndoEntry& e : state_.entries()) n += e.client_id() == client && !e.undone();
  return n;
}
int32_t UndoHistory::redo_depth(const std::string& client) const {
  int32_t n = 0;
  for (const persist::UndoEntry& e : state_.entries()) n += e.client_id() == client && e.undone();
  return n;
}

void UndoHistory::Describe(HistoryInfo* out) const {
  std::map<std::string, HistoryInfo::Person*> people;
  std::vector<std::string> order;
  for (const persist::UndoEntry& e : state_.entries()) {
    HistoryEntryInfo* i = out->add_entries();
    i->set_serial(e.serial());
    i->set_client_id(e.client_id());
    i->set_what(e.what());
    i->set_undone(e.undone());
    if (people.find(e.client_id()) == people.end()) {
      HistoryInfo::Person* p = out->add_people();
      p->set_client_id(e.client_id());
      people[e.client_id()] = p;
    }
  }
  // Undo lists oldest first; redo lists with the next redo last.
  for (const persist::UndoEntry& e : state_.entries()) {
    if (!e.undone()) people[e.client_id()]->add_undo(e.serial());
  }
  for (int i = state_.entries_size() - 1; i >= 0; --i) {
    const persist::UndoEntry& e = state_.entries(i);
    if (e.undone()) people[e.client_id()]->add_redo(e.serial());
  }
  out->set_bytes(bytes_);
  out->set_limit_bytes(limit_);
}

void UndoHistory::SaveTo(persist::UndoHistoryState* out) const {
  *out = state_;
  for (const auto& [id, now] : aliases_) {
    persist::IdAlias* a = out->add_aliases();
    a->set_id(id);
    a->set_now(now);
  }
}

void UndoHistory::RestoreFrom(const persist::UndoHistoryState& in) {
  state_ = in;
  state_.clear_aliases();
  aliases_.clear();
  for (const persist::IdAlias& a : in.aliases()) aliases_[a.id()] = a.now();
  Recount();
}

std::string UndoHistory::Who(const std::string& client, const std::string& asking) {
  if (client == asking) return "you";
  return absl::StrCat("another person (", client, ")");
}

std::string ActionName(const Command& c) {
  switch (c.kind_case()) {
    case Command::kAddPointForce:
      return "point force";
    case Command::kAddPressure:
      return c.add_pressure().pascals() >= 0 ? "inflate" : "deflate";
    case Command::kSetGravity:
      return "gravity";
    case Command::kRemoveLoad:
      return absl::StrCat("remove load ", c.remove_load().load_id());
    case Command::kFixRegion:
      return "pin";
    case Command::kUnfix:
      return absl::StrCat("unpin ", c.unfix().constraint_id());
    case Command::kPaintMaterial:
      return StrokeName(c, 1);
    case Command::kDrag:
      return "drag";
    case Command::kCurve:
      return "curve";
    case Command::kRevertToScene:
      return "revert to the scene";
    case Command::kEdit:
      break;
    default:
      return "command";
  }
  const TopologyEdit& e = c.edit();
  switch (e.kind_case()) {
    case TopologyEdit::kDeleteCells: {
      const int n = e.delete_cells().cells_size() + e.delete_cells().near_size();
      if (e.delete_cells().near_size() != 0) return absl::StrCat("delete ", n, Noun(" cell", " cells", n));
      return absl::StrCat("delete ", Noun("cell ", "cells ", n), IdList(e.delete_cells().cells()));
    }
    case TopologyEdit::kExtrudeFaces: {
      const int n = e.extrude_faces().faces_size() + e.extrude_faces().near_size();
      if (e.extrude_faces().near_size() != 0) {
        return absl::StrCat("extrude ", n, Noun(" face", " faces", n));
      }
      return absl::StrCat("extrude ", Noun("face ", "faces ", n), IdList(e.extrude_faces().faces()));
    }
    case TopologyEdit::kMergeFaces:
      if (e.merge_faces().near_size() != 0) return "merge two faces";
      return absl::StrCat("merge faces ", e.merge_faces().face_a(), " and ", e.merge_faces().face_b());
    case TopologyEdit::kSubdivideCells: {
      const int n = e.subdivide_cells().cells_size() + e.subdivide_cells().near_size();
      if (e.subdivide_cells().near_size() != 0) return absl::StrCat("subdivide ", n, Noun(" cell", " cells", n));
      return absl::StrCat("subdivide ", Noun("cell ", "cells ", n), IdList(e.subdivide_cells().cells()));
    }
    case TopologyEdit::kSharpEdges: {
      const int n = e.sharp_edges().edges_size();
      return absl::StrCat(e.sharp_edges().sharp() ? "sharpen " : "smooth ", n, Noun(" edge", " edges", n));
    }
    case TopologyEdit::kBake:
      return "bake";
    case TopologyEdit::KIND_NOT_SET:
      break;
  }
  return "edit";
}

std::string StrokeName(const Command& c, int32_t dabs) {
  const Material& m = c.paint_material().material();
  const char* kind = "material";
  if (m.preset() == Material::CLAY || m.preset() == Material::WAX || m.yield_strain() > 0) {
    kind = "clay";
  } else if (m.preset() == Material::RUBBER) {
    kind = "rubber";
  } else if (m.young_modulus() > 0) {
    kind = "stiffness";
  } else if (m.density() > 0) {
    kind = "mass";
  } else if (m.damping() > 0) {
    kind = "damping";
  }
  if (dabs <= 1) return absl::StrCat(kind, " paint");
  return absl::StrCat(kind, " stroke, ", dabs, " dabs");
}

}  // namespace dynsolid::server
