// SimCore's per-person undo: recording actions, and applying their
// inverses to the solid as it is now (server/history.h says the design).
#include <algorithm>
#include <chrono>
#include <optional>
#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "server/material_diff.h"
#include "server/sim_core.h"
#include "server/vec3.h"
#include "solver/common/status_macros.h"
#include "solver/scene/build.h"
#include "solver/sculpt/apply.h"
#include "solver/sculpt/revert.h"

namespace dynsolid::server {
namespace {

bool SameVec(const Vec3& a, const Vec3& b) {
  return a.x() == b.x() && a.y() == b.y() && a.z() == b.z();
}

std::string Show(const Vec3& v) { return absl::StrCat("(", v.x(), ", ", v.y(), ", ", v.z(), ")"); }

bool IsPaintOnly(const persist::UndoEntry& e) {
  for (const persist::UndoChange& c : e.changes()) {
    if (!c.has_paint()) return false;
  }
  return e.changes_size() > 0;
}

// "client\ntext" (history.h SetMesh) as words for `asking`.
std::string Cause(const std::string& cause, const std::string& asking) {
  const size_t nl = cause.find('\n');
  if (nl == std::string::npos) return "the session's start";
  return absl::StrCat(UndoHistory::Who(cause.substr(0, nl), asking), ": ", cause.substr(nl + 1));
}

}  // namespace


std::unique_ptr<SimCore::Before> SimCore::CaptureBefore(const Command& c) const {
  auto b = std::make_unique<Before>();
  switch (c.kind_case()) {
    case Command::kRemoveLoad:
      for (solid::Solid::LoadInfo& l : solid_->ActiveLoads()) {
        if (l.id == c.remove_load().load_id()) b->load = std::move(l);
      }
      break;
    case Command::kUnfix:
      for (solid::Solid::ConstraintInfo& k : solid_->ActiveConstraints()) {
        if (k.id == c.unfix().constraint_id()) b->constraint = std::move(k);
      }
      break;
    case Command::kSetGravity:
      b->gravity = ToVec3(solid_->gravity());
      break;
    case Command::kPaintMaterial:
      b->material = solid_->SaveStateParts().section;
      break;
    case Command::kEdit:
      b->scene = scene_;
      b->edit = c.edit();
      // A bake left to the server: the positions ApplyEdit takes.
      if (b->edit.has_bake() && b->edit.bake().rest_positions_size() == 0) {
        FillBake(*solid_, *b->edit.mutable_bake());
      }
      break;
    case Command::kRevertToScene:
      b->state = solid_->SaveState();
      b->scene = scene_;
      break;
    default:
      break;
  }
  return b;
}

absl::Status SimCore::Record(const CommandRequest& request, const Before& before,
                             const CommandReply& reply) {
  const Command& c = request.command();
  const std::string& client = request.client_id();
  // A drag's or curve's release belongs to the drag's entry, whoever
  // released it (the server does when a command stream ends).
  if (c.kind_case() == Command::kRemoveLoad && before.load.has_value() &&
      (before.load->kind == solid::Solid::LoadInfo::Kind::kDrag ||
       before.load->kind == solid::Solid::LoadInfo::Kind::kCurve)) {
    if (persist::UndoEntry* e = history_.FindHeldDrag(before.load->id)) {
      for (persist::UndoChange& ch : *e->mutable_changes()) {
        if (ch.has_drag() && history_.Resolve(ch.drag().id()) == before.load->id) {
          ch.mutable_drag()->set_released(true);
        }
      }
      history_.Commit(e->serial());
    }
    return absl::OkStatus();
  }
  if (absl::StartsWith(client, "server:")) return absl::OkStatus();
  const bool drag = c.kind_case() == Command::kDrag || c.kind_case() == Command::kCurve;
  persist::UndoEntry* e = history_.Begin(client, drag ? 0 : c.gesture());
  const bool first = e->commands() == 0;
  e->set_commands(e->commands() + 1);
  switch (c.kind_case()) {
    case Command::kAddPointForce: {
      persist::LoadChange* l = e->add_changes()->mutable_load_added();
      l->set_id(reply.load_id());
      *l->mutable_point_force() = c.add_point_force();
      break;
    }
    case Command::kAddPressure: {
      persist::LoadChange* l = e->add_changes()->mutable_load_added();
      l->set_id(reply.load_id());
      *l->mutable_pressure() = c.add_pressure();
      break;
    }
    case Command::kRemoveLoad: {
      persist::LoadChange* l = e->add_changes()->mutable_load_removed();
      l->set_id(c.remove_load().load_id());
      if (before.load.has_value() && before.load->kind == solid::Solid::LoadInfo::Kind::kPressure) {
        *l->mutable_pressure()->mutable_region() = before.load->region;
        l->mutable_pressure()->set_pascals(before.load->pascals);
      } else if (before.load.has_value() && !before.load->material_points.empty()) {
        *l->mutable_point_force()->mutable_position() = ToVec3(before.load->material_points[0]);
        *l->mutable_point_force()->mutable_force() = ToVec3(before.load->force);
      }
      break;
    }
    case Command::kFixRegion: {
      persist::PinChange* p = e->add_changes()->mutable_pin_added();
      p->set_id(reply.constraint_id());
      *p->mutable_region() = c.fix_region();
      break;
    }
    case Command::kUnfix: {
      persist::PinChange* p = e->add_changes()->mutable_pin_removed();
      p->set_id(c.unfix().constraint_id());
      if (before.constraint.has_value()) {
        *p->mutable_region() = before.constraint->region;
        p->set_control_points(static_cast<int32_t>(before.constraint->control_points.size()));
      }
      break;
    }
    case Command::kSetGravity: {
      persist::GravityChange* g = e->add_changes()->mutable_gravity();
      *g->mutable_before() = before.gravity;
      *g->mutable_after() = c.set_gravity();
      break;
    }
    case Command::kPaintMaterial: {
      // A stroke's dabs add to one change while the mesh stays.
      persist::PaintChange* p = nullptr;
      if (e->changes_size() > 0 && e->changes(e->changes_size() - 1).has_paint() &&
          e->changes(e->changes_size() - 1).paint().mesh() == history_.mesh()) {
        p = e->mutable_changes(e->changes_size() - 1)->mutable_paint();
      } else {
        p = e->add_changes()->mutable_paint();
        p->set_mesh(history_.mesh());
      }
      ASSIGN_OR_RETURN(ElementMaterials was, ParseMaterialSection(*before.material));
      ASSIGN_OR_RETURN(ElementMaterials now, MaterialsOf(*solid_));
      RETURN_IF_ERROR(AddPaintDiff(was, now, p));
      break;
    }
    case Command::kEdit: {
      persist::EditChange* x = e->add_changes()->mutable_edit();
      *x->mutable_edit() = before.edit;
      if (before.scene == original_) {
        x->set_before_original(true);
      } else {
        *x->mutable_before() = *before.scene;
      }
      x->set_mesh_before(history_.mesh());
      x->set_mesh_after(history_.NewMesh());
      history_.SetMesh(x->mesh_after(), absl::StrCat(client, "\n\"", ActionName(c), "\""));
      break;
    }
    case Command::kDrag:
    case Command::kCurve: {
      persist::DragChange* d = e->add_changes()->mutable_drag();
      d->set_id(reply.load_id());
      d->set_curve(c.kind_case() == Command::kCurve);
      break;
    }
    case Command::kRevertToScene: {
      persist::RevertChange* r = e->add_changes()->mutable_revert();
      r->set_solid_state(before.state);
      if (before.scene == original_) {
        r->set_scene_original(true);
      } else {
        *r->mutable_scene() = *before.scene;
      }
      r->set_mesh_before(history_.mesh());
      history_.SetMesh(0, absl::StrCat(client, "\nrevert to the scene"));
      break;
    }
    default:
      break;
  }
  // Plain names: the action's, a stroke's with its dabs, a held load's
  // release ("inflate, released": a press-and-hold gesture).
  auto releases_own_load = [&] {
    if (c.kind_case() != Command::kRemoveLoad) return false;
    for (const persist::UndoChange& ch : e->changes()) {
      if (ch.has_load_added() && history_.Resolve(ch.load_added().id()) == c.remove_load().load_id()) {
        return true;
      }
    }
    return false;
  };
  if (IsPaintOnly(*e)) {
    e->set_what(StrokeName(c, e->commands()));
  } else if (!first && e->commands() == 2 && releases_own_load()) {
    e->set_what(absl::StrCat(e->what(), ", released"));
  } else if (first) {
    e->set_what(ActionName(c));
  } else if (e->commands() == 2) {
    e->set_what(absl::StrCat(e->what(), " and more (2 commands)"));
  } else {
    const size_t at = e->what().rfind(" (");
    e->set_what(absl::StrCat(e->what().substr(0, at), " (", e->commands(), " commands)"));
  }
  history_.Commit(e->serial());
  return absl::OkStatus();
}

bool SimCore::HasLoad(int64_t id) const {
  for (const solid::Solid::LoadInfo& l : solid_->ActiveLoads()) {
    if (l.id == id) return true;
  }
  return false;
}

bool SimCore::HasPin(int64_t id) const {
  const std::vector<int64_t> ids = solid_->constraint_ids();
  return std::binary_search(ids.begin(), ids.end(), id);
}

std::string SimCore::Refusal(bool undo, const persist::UndoEntry& entry) {
  const char* verb = undo ? "undo" : "redo";
  return absl::StrCat("command.", verb, ": cannot ", verb, " \"", entry.what(), "\" (entry ",
                      entry.serial(), "): ");
}

absl::Status SimCore::AddBack(const persist::UndoChange& change, int64_t id) {
  absl::StatusOr<int64_t> now = absl::InternalError("nothing recorded to put back");
  const persist::LoadChange* l = change.has_load_added()     ? &change.load_added()
                                 : change.has_load_removed() ? &change.load_removed()
                                                             : nullptr;
  const persist::PinChange* p = change.has_pin_added()     ? &change.pin_added()
                                : change.has_pin_removed() ? &change.pin_removed()
                                                           : nullptr;
  if (l != nullptr && l->has_point_force()) now = solid_->AddPointForce(l->point_force());
  if (l != nullptr && l->has_pressure()) now = solid_->AddPressure(l->pressure());
  if (p != nullptr && p->has_region()) now = solid_->FixRegion(p->region());
  if (!now.ok()) return now.status();
  const std::string own = owner(history_.Resolve(id));
  history_.Alias(id, *now);
  if (!own.empty()) owners_[*now] = own;
  return absl::OkStatus();
}

absl::Status SimCore::CheckChange(const persist::UndoEntry& entry,
                                  const persist::UndoChange& change, bool undo,
                                  const std::string& client) const {
  const std::string cause = Cause(history_.mesh_cause(), client);
  switch (change.kind_case()) {
    case persist::UndoChange::kEdit: {
      const persist::EditChange& x = change.edit();
      if (history_.mesh() != (undo ? x.mesh_after() : x.mesh_before())) {
        return absl::FailedPreconditionError(absl::StrCat(
            Refusal(undo, entry), cause,
            undo ? " changed the control mesh after it and builds on its cells; that has to be "
                   "undone first. Nothing changed."
                 : " changed the control mesh since; the edit was made on the one before. "
                   "Nothing changed."));
      }
      break;
    }
    case persist::UndoChange::kGravity: {
      const Vec3 now = ToVec3(solid_->gravity());
      const Vec3& want = undo ? change.gravity().after() : change.gravity().before();
      if (!SameVec(now, want)) {
        return absl::FailedPreconditionError(absl::StrCat(
            Refusal(undo, entry), "the gravity was set to ", Show(now),
            " m/s^2 since, by a later action. Nothing changed."));
      }
      break;
    }
    default:
      break;
  }
  return absl::OkStatus();
}

absl::Status SimCore::UndoEdit(const persist::UndoEntry& entry, const persist::EditChange& change,
                               const std::string& client) {
  const Scene& before = change.before_original() ? *original_ : change.before();
  absl::StatusOr<scene::Discretization> d = absl::InternalError("no discretization");
  if (change.before_original()) {
    if (factory_ == nullptr) {
      return absl::FailedPreconditionError("this session cannot rebuild its solid (no factory)");
    }
    ASSIGN_OR_RETURN(std::shared_ptr<solid::Solid> s, factory_(nullptr));
    d = s->discretization();
  } else {
    d = scene::BuildDiscretization(before, "", std::nullopt);
  }
  RETURN_IF_ERROR(d.status());
  ASSIGN_OR_RETURN(sculpt::AppliedEdit r,
                   sculpt::RevertEdit(before, *std::move(d), *solid_, change.edit()));
  solid_ = std::move(r.solid);
  // The scene the rebuilt solid was fingerprinted with (its loads and pins
  // taken out), never original_ even when equal in mesh: a revert saves
  // the solid's state with this scene and its undo rebuilds from it.
  scene_ = std::make_shared<const Scene>(std::move(r.scene));
  ++fields_version_;
  history_.SetMesh(change.mesh_before(),
                   absl::StrCat(client, "\nthe undo of \"", entry.what(), "\""));
  return absl::OkStatus();
}

absl::Status SimCore::RedoEdit(const persist::UndoEntry& entry, const persist::EditChange& change,
                               const std::string& client) {
  ASSIGN_OR_RETURN(sculpt::AppliedEdit r, sculpt::ApplyEdit(*scene_, *solid_, change.edit()));
  solid_ = std::move(r.solid);
  scene_ = std::make_shared<const Scene>(std::move(r.scene));
  ++fields_version_;
  history_.SetMesh(change.mesh_after(), absl::StrCat(client, "\n\"", entry.what(), "\""));
  return absl::OkStatus();
}

absl::Status SimCore::PutBackState(const persist::RevertChange& change) {
  std::shared_ptr<const Scene> scene =
      change.scene_original() ? original_ : std::make_shared<const Scene>(change.scene());
  std::shared_ptr<solid::Solid> target = solid_;
  if (scene != scene_) {
    if (factory_ == nullptr) {
      return absl::FailedPreconditionError("this session cannot rebuild its solid (no factory)");
    }
    ASSIGN_OR_RETURN(target, factory_(scene == original_ ? nullptr : scene.get()));
  }
  RETURN_IF_ERROR(
      target->RestoreStateAtClock(change.solid_state(), solid_->time(), solid_->steps()));
  if (target != solid_) {
    target->set_topology_version(solid_->topology_version() + 1);
    solid_ = std::move(target);
  }
  scene_ = std::move(scene);
  ++fields_version_;
  last_error_.clear();
  return absl::OkStatus();
}

absl::Status SimCore::RevertToScene() {
  if (factory_ == nullptr) {
    return absl::FailedPreconditionError(
        "command.revert_to_scene: this session cannot rebuild its solid (no factory)");
  }
  ASSIGN_OR_RETURN(std::shared_ptr<solid::Solid> fresh, factory_(nullptr));
  RETURN_IF_ERROR(fresh->RestoreStateAtClock(fresh->SaveState(), solid_->time(), solid_->steps()));
  fresh->set_topology_version(solid_->topology_version() + 1);
  solid_ = std::move(fresh);
  scene_ = original_;
  ++fields_version_;
  last_error_.clear();
  return absl::OkStatus();
}

absl::Status SimCore::ApplyChange(const persist::UndoEntry& entry, persist::UndoChange& change,
                                  bool undo, const std::string& client, bool* did) {
  *did = false;
  switch (change.kind_case()) {
    case persist::UndoChange::kLoadAdded:
    case persist::UndoChange::kLoadRemoved:
    case persist::UndoChange::kPinAdded:
    case persist::UndoChange::kPinRemoved: {
      const bool pin = change.has_pin_added() || change.has_pin_removed();
      const bool added = change.has_load_added() || change.has_pin_added();
      const int64_t id = change.has_load_added()     ? change.load_added().id()
                         : change.has_load_removed() ? change.load_removed().id()
                         : change.has_pin_added()    ? change.pin_added().id()
                                                     : change.pin_removed().id();
      if (undo == added) {  // take it away, if it is still there
        const int64_t now = history_.Resolve(id);
        if (!(pin ? HasPin(now) : HasLoad(now))) return absl::OkStatus();
        RETURN_IF_ERROR(pin ? solid_->Unfix(now) : solid_->RemoveLoad(now));
      } else {
        RETURN_IF_ERROR(AddBack(change, id));
      }
      *did = true;
      return absl::OkStatus();
    }
    case persist::UndoChange::kGravity:
      RETURN_IF_ERROR(
          solid_->SetGravity(undo ? change.gravity().before() : change.gravity().after()));
      *did = true;
      return absl::OkStatus();
    case persist::UndoChange::kPaint: {
      const solid::SavedState now = solid_->SaveStateParts();
      ASSIGN_OR_RETURN(ElementMaterials m, MaterialsOf(*solid_));
      ASSIGN_OR_RETURN(int32_t flipped, FlipPaint(change.paint(), undo, &m));
      if (flipped == 0) return absl::OkStatus();
      RETURN_IF_ERROR(solid_->RestoreStateAtClock(StateWithMaterial(now, WriteMaterialSection(m)),
                                                  solid_->time(), solid_->steps()));
      ++fields_version_;
      *did = true;
      return absl::OkStatus();
    }
    case persist::UndoChange::kEdit:
      RETURN_IF_ERROR(undo ? UndoEdit(entry, change.edit(), client)
                           : RedoEdit(entry, change.edit(), client));
      *did = true;
      return absl::OkStatus();
    case persist::UndoChange::kDrag: {
      // Never put back; an undo lets go of one still held.
      if (!undo || change.drag().released()) return absl::OkStatus();
      const int64_t now = history_.Resolve(change.drag().id());
      if (HasLoad(now)) RETURN_IF_ERROR(solid_->RemoveLoad(now));
      change.mutable_drag()->set_released(true);
      *did = true;
      return absl::OkStatus();
    }
    case persist::UndoChange::kRevert:
      if (undo) {
        RETURN_IF_ERROR(PutBackState(change.revert()));
        history_.SetMesh(change.revert().mesh_before(),
                         absl::StrCat(client, "\nthe undo of \"", entry.what(), "\""));
      } else {
        RETURN_IF_ERROR(RevertToScene());
        history_.SetMesh(0, absl::StrCat(client, "\nrevert to the scene"));
      }
      *did = true;
      return absl::OkStatus();
    case persist::UndoChange::KIND_NOT_SET:
      break;
  }
  return absl::OkStatus();
}

absl::Status SimCore::UndoRedo(bool undo, const std::string& client, CommandReply* reply) {
  const auto t0 = std::chrono::steady_clock::now();
  const char* verb = undo ? "undo" : "redo";
  persist::UndoEntry* e = undo ? history_.NextUndo(client) : history_.NextRedo(client);
  if (e == nullptr) {
    return absl::FailedPreconditionError(absl::StrCat(
        "command.", verb, ": you have nothing to ", verb, " (", history_.undo_depth(client),
        " of your actions to undo, ", history_.redo_depth(client), " to redo; undo takes back "
        "only your own actions)"));
  }
  // A revert to the scene and what came before or after it: a revert
  // puts everything back, so it goes back only when nothing is on top of
  // it, and what came before it waits until it is undone.
  const bool revert = e->changes_size() == 1 && e->changes(0).has_revert();
  for (const persist::UndoEntry& o : history_.entries()) {
    if (o.undone() || o.serial() <= e->serial()) continue;
    if (revert) {
      return absl::FailedPreconditionError(absl::StrCat(
          Refusal(undo, *e), UndoHistory::Who(o.client_id(), client), ": \"", o.what(),
          "\" (entry ", o.serial(), ") came after it and would be taken away too; that has to "
          "be undone first. Nothing changed."));
    }
    if (o.changes_size() == 1 && o.changes(0).has_revert()) {
      return absl::FailedPreconditionError(absl::StrCat(
          Refusal(undo, *e), "the session was reverted to the scene after it (",
          UndoHistory::Who(o.client_id(), client), ", entry ", o.serial(),
          "); that revert has to be undone first. Nothing changed."));
    }
  }
  const bool skip = !undo && e->noop();
  const int n = e->changes_size();
  if (!skip) {
    for (int k = 0; k < n; ++k) {
      RETURN_IF_ERROR(CheckChange(*e, e->changes(undo ? n - 1 - k : k), undo, client));
    }
  }
  bool any = false;
  if (!skip) {
    // An entry of several changes goes back whole if one of them fails.
    std::shared_ptr<solid::Solid> old_solid = solid_;
    std::shared_ptr<const Scene> old_scene = scene_;
    std::string saved;
    persist::UndoHistoryState saved_history;
    if (n > 1) {
      saved = solid_->SaveState();
      history_.SaveTo(&saved_history);
    }
    for (int k = 0; k < n; ++k) {
      bool did = false;
      const absl::Status s =
          ApplyChange(*e, *e->mutable_changes(undo ? n - 1 - k : k), undo, client, &did);
      if (!s.ok()) {
        const std::string head = Refusal(undo, *e);
        if (n > 1) {
          solid_ = std::move(old_solid);
          scene_ = std::move(old_scene);
          (void)solid_->RestoreStateAtClock(saved, solid_->time(), solid_->steps());
          history_.RestoreFrom(saved_history);
        }
        return absl::Status(s.code(), absl::StrCat(head, s.message(), ". Nothing changed."));
      }
      any |= did;
    }
  }
  std::string what = e->what();
  const int64_t serial = e->serial();
  if (undo && !any) absl::StrAppend(&what, " (nothing of it was left to take back)");
  history_.MarkUndone(e, undo, undo && !any);
  HistoryReport* r = reply->mutable_history();
  r->set_undo_depth(history_.undo_depth(client));
  r->set_redo_depth(history_.redo_depth(client));
  r->set_bytes(history_.bytes());
  r->set_limit_bytes(history_.limit_bytes());
  r->set_what(what);
  r->set_serial(serial);
  r->set_hold_ms(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  return absl::OkStatus();
}

}  // namespace dynsolid::server
