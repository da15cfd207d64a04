#include "server/sim_core.h"

#include <algorithm>
#include <chrono>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/scene/scene_loader.h"
#include "solver/sculpt/apply.h"

namespace dynsolid::server {
namespace {

constexpr int64_t kMaxStepCount = 1'000'000;

// The solver names its arguments ("point_force.position: ..."); a command
// reply names the request field ("command.add_point_force.position: ...").
absl::Status Rename(const absl::Status& s, absl::string_view solver_name,
                    absl::string_view command_field) {
  if (s.ok()) return s;
  const std::string field = absl::StrCat("command.", command_field);
  absl::string_view m = s.message();
  if (absl::StartsWith(m, solver_name) && m.size() > solver_name.size() &&
      (m[solver_name.size()] == '.' || m[solver_name.size()] == ':' ||
       m[solver_name.size()] == ' ' || m[solver_name.size()] == '[')) {
    return absl::Status(s.code(), absl::StrCat(field, m.substr(solver_name.size())));
  }
  return absl::Status(s.code(), absl::StrCat(field, ": ", m));
}

// Commands that change the solid and can be undone (service.proto Undo).
bool Undoable(const Command& c) {
  switch (c.kind_case()) {
    case Command::kAddPointForce:
    case Command::kAddPressure:
    case Command::kSetGravity:
    case Command::kRemoveLoad:
    case Command::kFixRegion:
    case Command::kUnfix:
    case Command::kPaintMaterial:
    case Command::kEdit:
    case Command::kDrag:
    case Command::kCurve:
    case Command::kRevertToScene:
      return true;
    default:
      return false;
  }
}

std::vector<Eigen::Vector3d> Targets(const MoveDrag& m) {
  std::vector<Eigen::Vector3d> out;
  if (m.targets_size() == 0) {
    out.emplace_back(m.target().x(), m.target().y(), m.target().z());
  }
  for (const Vec3& v : m.targets()) out.emplace_back(v.x(), v.y(), v.z());
  return out;
}

void SetVec3(const Eigen::Vector3d& x, Vec3* v) {
  v->set_x(x.x());
  v->set_y(x.y());
  v->set_z(x.z());
}

void SetStatus(const absl::Status& s, CommandReply* reply) {
  reply->set_code(static_cast<int32_t>(s.code()));
  reply->set_message(std::string(s.message()));
}

}  // namespace

struct SimCore::Prebuilt {
  // A topology edit's prepared solid, or the error preparing it gave.
  std::optional<absl::StatusOr<sculpt::PreparedEdit>> edit;
  // A paint's prepared material, or the error preparing it gave.
  std::optional<absl::StatusOr<std::shared_ptr<solid::Solid::PreparedPaint>>> paint;
  // An unfix's prepared stable step, or the error preparing it gave.
  std::optional<absl::StatusOr<std::shared_ptr<solid::Solid::PreparedUnfix>>> unfix;
};

uint64_t SimCore::LastSeq(const std::string& client_id) const {
  auto it = clients_.find(client_id);
  return it == clients_.end() ? 0 : it->second.last_seq;
}

bool SimCore::NeedsBuild(const CommandRequest& request) const {
  auto it = clients_.find(request.client_id());
  if (it != clients_.end() && request.seq() <= it->second.last_seq) return false;  // an old seq
  const Command& c = request.command();
  if (c.kind_case() == Command::kEdit || c.kind_case() == Command::kPaintMaterial ||
      c.kind_case() == Command::kUnfix) {
    return true;
  }
  // Undo and redo apply in line (an edit's inverse holds the loop while
  // it rebuilds the solid).
  return false;
}

bool SimCore::MayPassBuild(const Command& building, const Command& command) {
  switch (building.kind_case()) {
    case Command::kPaintMaterial:
    case Command::kEdit:
    case Command::kUnfix:
      break;
    default:  // an undo's or redo's build reads the history
      return false;
  }
  switch (command.kind_case()) {
    case Command::kAddPointForce:
    case Command::kAddPressure:
    case Command::kSetGravity:
    case Command::kRemoveLoad:
    case Command::kDrag:
    case Command::kCurve:
    case Command::kMoveDrag:
      return true;
    default:
      return false;
  }
}

void SimCore::Stamp(CommandRequest& request) const {
  Command* c = request.mutable_command();
  if (c->kind_case() != Command::kEdit || !c->edit().has_bake() ||
      c->edit().bake().rest_positions_size() != 0) {
    return;
  }
  FillBake(*solid_, *c->mutable_edit()->mutable_bake());
}

void SimCore::FillBake(const solid::Solid& solid, Bake& bake) {
  const Points& p = solid.control_positions();
  bake.mutable_rest_positions()->Reserve(static_cast<int>(p.size()));
  for (int64_t i = 0; i < p.rows(); ++i) {
    for (int k = 0; k < 3; ++k) bake.add_rest_positions(p(i, k));
  }
}

std::function<std::shared_ptr<SimCore::Prebuilt>()> SimCore::Prebuild(
    const CommandRequest& request) const {
  const Command& c = request.command();
  if (c.kind_case() == Command::kEdit) {
    // Keeps the scene and the solid alive; reads only what stepping leaves
    // alone (sculpt::PrepareEdit).
    return [scene = scene_, solid = solid_, edit = c.edit()]() {
      auto out = std::make_shared<Prebuilt>();
      out->edit = sculpt::PrepareEdit(*scene, *solid, edit);
      return out;
    };
  }
  if (c.kind_case() == Command::kUnfix) {
    // Solid::PrepareUnfix estimates on a model of its own.
    return [solid = solid_, id = c.unfix().constraint_id()]() {
      auto out = std::make_shared<Prebuilt>();
      out->unfix = solid->PrepareUnfix(id);
      return out;
    };
  }
  if (c.kind_case() == Command::kPaintMaterial) {
    // Solid::PreparePaint reads only what stepping leaves alone.
    return [solid = solid_, paint = c.paint_material()]() {
      auto out = std::make_shared<Prebuilt>();
      out->paint = solid->PreparePaint(paint);
      return out;
    };
  }
  // NeedsBuild says no to anything else.
  return [] { return std::make_shared<Prebuilt>(); };
}

absl::Status CheckClientIdCharacters(const std::string& id) {
  if (id.size() > 64) {
    return absl::InvalidArgumentError(absl::StrCat(
        "client_id: must have at most 64 characters, got ", id.size()));
  }
  for (const char c : id) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      return absl::InvalidArgumentError("client_id: must not contain control characters");
    }
  }
  return absl::OkStatus();
}

absl::Status CheckCommandEnvelope(const CommandRequest& request) {
  const std::string& id = request.client_id();
  if (id.empty() || id.size() > 64) {
    return absl::InvalidArgumentError(absl::StrCat(
        "client_id: must have 1 to 64 characters, got ", id.size()));
  }
  if (absl::Status s = CheckClientIdCharacters(id); !s.ok()) return s;
  if (absl::StartsWith(id, "server:")) {
    return absl::InvalidArgumentError(absl::StrCat(
        "client_id: \"", id, "\" starts with \"server:\", which the server keeps for its own "
        "commands"));
  }
  if (request.seq() < 1) return absl::InvalidArgumentError("seq: must be >= 1, got 0");
  return absl::OkStatus();
}

SimCore::SimCore(std::shared_ptr<solid::Solid> solid, CoreOptions options, bool start_paused,
                 Scene scene, SolidFactory factory)
    : solid_(std::move(solid)),
      options_(options),
      paused_(start_paused),
      original_(std::make_shared<const Scene>(std::move(scene))),
      scene_(original_),
      factory_(std::move(factory)),
      history_(options.undo_bytes) {}

void SimCore::Remember(Client& client, const CommandReply& reply) {
  client.last_seq = reply.seq();
  client.replies.push_back(reply);
  while (static_cast<int>(client.replies.size()) > options_.answer_cache) {
    client.replies.pop_front();
  }
}

void SimCore::RecordOwner(const std::string& client_id, const CommandReply& reply) {
  int64_t id = 0;
  switch (reply.result_case()) {
    case CommandReply::kLoadId:
      id = reply.load_id();
      break;
    case CommandReply::kConstraintId:
      id = reply.constraint_id();
      break;
    default:
      return;
  }
  owners_[id] = client_id;
  // Forget the oldest owners of items no longer active, in batches (an
  // undo may bring a removed item back: keep the newest kKeptOwners).
  const std::vector<int64_t> loads = solid_->load_ids();
  const std::vector<int64_t> constraints = solid_->constraint_ids();
  if (owners_.size() <= loads.size() + constraints.size() + 2 * kKeptOwners) return;
  std::vector<int64_t> inactive;
  for (const auto& [item, client] : owners_) {
    if (!std::binary_search(loads.begin(), loads.end(), item) &&
        !std::binary_search(constraints.begin(), constraints.end(), item)) {
      inactive.push_back(item);
    }
  }
  if (inactive.size() <= kKeptOwners) return;
  std::sort(inactive.begin(), inactive.end());
  for (size_t i = 0; i + kKeptOwners < inactive.size(); ++i) owners_.erase(inactive[i]);
}

const std::string& SimCore::owner(int64_t id) const {
  static const std::string* const kNone = new std::string();
  auto it = owners_.find(id);
  return it == owners_.end() ? *kNone : it->second;
}

void SimCore::DescribeLoads(InspectReply* reply) const {
  using Kind = solid::Solid::LoadInfo::Kind;
  for (const solid::Solid::LoadInfo& l : solid_->ActiveLoads()) {
    ActiveLoad* a = reply->add_loads();
    a->set_id(l.id);
    switch (l.kind) {
      case Kind::kPointForce:
        a->set_kind("point_force");
        SetVec3(l.force, a->mutable_force());
        break;
      case Kind::kPressure:
        a->set_kind("pressure");
        a->set_pressure(l.pascals);
        *a->mutable_region() = l.region;
        a->mutable_surface_quads()->Assign(l.quads.begin(), l.quads.end());
        break;
      case Kind::kDrag:
        a->set_kind("drag");
        a->set_stiffness(l.stiffness);
        break;
      case Kind::kCurve:
        a->set_kind("curve");
        a->set_stiffness(l.stiffness);
        *a->mutable_curve() = l.curve;
        break;
    }
    if (l.kind == Kind::kCurve) {
      for (const Eigen::Vector3d& x : l.material_points) SetVec3(x, a->add_material_points());
      for (const Eigen::Vector3d& x : l.positions) SetVec3(x, a->add_positions());
      for (const Eigen::Vector3d& x : l.targets) SetVec3(x, a->add_targets());
    } else {
      if (!l.material_points.empty()) SetVec3(l.material_points[0], a->mutable_material_point());
      if (!l.positions.empty()) SetVec3(l.positions[0], a->mutable_position());
      if (!l.targets.empty()) SetVec3(l.targets[0], a->mutable_target());
    }
    a->set_client_id(owner(l.id));
  }
  for (const solid::Solid::ConstraintInfo& c : solid_->ActiveConstraints()) {
    ActiveConstraint* a = reply->add_constraints();
    a->set_id(c.id);
    *a->mutable_region() = c.region;
    a->set_control_points(static_cast<int32_t>(c.control_points.size()));
    a->mutable_control_point_indices()->Assign(c.control_points.begin(), c.control_points.end());
    a->set_client_id(owner(c.id));
  }
  SetVec3(solid_->gravity(), reply->mutable_gravity());
}

SimCore::Outcome SimCore::Process(const CommandRequest& request, CommandReply* reply,
                                  std::shared_ptr<Prebuilt> prebuilt) {
  reply->Clear();
  reply->set_client_id(request.client_id());
  reply->set_seq(request.seq());
  Client& client = clients_[request.client_id()];
  if (request.seq() <= client.last_seq) {
    for (const CommandReply& r : client.replies) {
      if (r.seq() == request.seq()) {
        *reply = r;
        reply->set_duplicate(true);
        return Outcome::kDuplicate;
      }
    }
    reply->set_applied_step(-1);
    SetStatus(absl::OutOfRangeError(absl::StrCat(
                  "seq: ", request.seq(), " is not above client ", request.client_id(),
                  "'s last applied seq ", client.last_seq,
                  " and no answer to it is kept (the server keeps the last ",
                  options_.answer_cache, " per client)")),
              reply);
    return Outcome::kUnknown;
  }
  reply->set_applied_step(solid_->steps());
  const Command& command = request.command();
  const bool undoable = Undoable(command);
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<Before> before;
  if (undoable) before = CaptureBefore(command);
  absl::Status s = command.kind_case() == Command::kUndo || command.kind_case() == Command::kRedo
                       ? UndoRedo(command.kind_case() == Command::kUndo, request.client_id(), reply)
                       : Apply(command, reply, prebuilt.get());
  if (s.ok() && undoable) s = Record(request, *before, *reply);
  if (s.ok()) RecordOwner(request.client_id(), *reply);
  last_hold_ms_ =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  SetStatus(s, reply);
  reply->set_hold_ms(last_hold_ms_);
  Remember(client, *reply);
  if (s.ok()) {
    ++applied_;
    return Outcome::kApplied;
  }
  ++rejected_;
  return Outcome::kRejected;
}

absl::Status SimCore::Apply(const Command& c, CommandReply* reply, Prebuilt* prebuilt) {
  if (absl::Status s = scene::ValidateValues(c, "command"); !s.ok()) return s;
  switch (c.kind_case()) {
    case Command::kAddPointForce: {
      absl::StatusOr<int64_t> id = solid_->AddPointForce(c.add_point_force());
      if (!id.ok()) return Rename(id.status(), "point_force", "add_point_force");
      reply->set_load_id(*id);
      return absl::OkStatus();
    }
    case Command::kAddPressure: {
      absl::StatusOr<int64_t> id = solid_->AddPressure(c.add_pressure());
      if (!id.ok()) return Rename(id.status(), "pressure", "add_pressure");
      reply->set_load_id(*id);
      return absl::OkStatus();
    }
    case Command::kSetGravity:
      return Rename(solid_->SetGravity(c.set_gravity()), "gravity", "set_gravity");
    case Command::kRemoveLoad:
      return Rename(solid_->RemoveLoad(c.remove_load().load_id()), "load_id",
                    "remove_load.load_id");
    case Command::kFixRegion: {
      absl::StatusOr<int64_t> id = solid_->FixRegion(c.fix_region());
      if (!id.ok()) return Rename(id.status(), "region", "fix_region");
      reply->set_constraint_id(*id);
      return absl::OkStatus();
    }
    case Command::kUnfix: {
      absl::Status s;
      if (prebuilt != nullptr && prebuilt->unfix.has_value()) {
        s = prebuilt->unfix->ok() ? solid_->ApplyUnfix(***prebuilt->unfix)
                                  : prebuilt->unfix->status();
      } else {
        s = solid_->Unfix(c.unfix().constraint_id());
      }
      return Rename(s, "constraint_id", "unfix.constraint_id");
    }
    case Command::kPaintMaterial: {
      absl::Status s;
      if (prebuilt != nullptr && prebuilt->paint.has_value()) {
        s = prebuilt->paint->ok() ? solid_->ApplyPaint(***prebuilt->paint)
                                  : prebuilt->paint->status();
      } else {
        s = solid_->PaintMaterial(c.paint_material());
      }
      if (!s.ok()) return Rename(s, "paint", "paint_material");
      ++fields_version_;
      return s;
    }
    case Command::kPause:
      paused_ = true;
      steps_remaining_ = 0;
      return absl::OkStatus();
    case Command::kResume:
      paused_ = false;
      steps_remaining_ = 0;
      return absl::OkStatus();
    case Command::kStep: {
      const int64_t n = c.step().count();
      if (n < 1 || n > kMaxStepCount) {
        return absl::InvalidArgumentError(absl::StrCat(
            "command.step.count: must be in [1, ", kMaxStepCount, "], got ", n));
      }
      if (steps_remaining_ > kMaxStepCount - n) {
        return absl::InvalidArgumentError(absl::StrCat(
            "command.step.count: ", n, " more steps would leave more than ", kMaxStepCount,
            " to take (", steps_remaining_, " are left)"));
      }
      paused_ = true;
      steps_remaining_ += n;
      return absl::OkStatus();
    }
    case Command::kSave:
      if (!options_.can_save) {
        return absl::FailedPreconditionError(
            "command.save: this server runs without --data-dir; there is nowhere to save");
      }
      save_requested_ = true;
      reply->mutable_saved()->set_step(solid_->steps());
      return absl::OkStatus();
    case Command::kEdit:
      return ApplyEdit(c.edit(), reply, prebuilt);
    case Command::kDrag: {
      absl::StatusOr<int64_t> id = solid_->AddDrag(c.drag());
      if (!id.ok()) return Rename(id.status(), "drag", "drag");
      reply->set_load_id(*id);
      return absl::OkStatus();
    }
    case Command::kCurve: {
      absl::StatusOr<int64_t> id = solid_->AddCurveDrag(c.curve());
      if (!id.ok()) return Rename(id.status(), "curve", "curve");
      reply->set_load_id(*id);
      return absl::OkStatus();
    }
    case Command::kMoveDrag:
      return Rename(solid_->MoveDrag(c.move_drag().load_id(), Targets(c.move_drag())),
                    "move_drag", "move_drag");
    case Command::kUndo:
    case Command::kRedo:
      // Process passes the sender (UndoRedo); Apply has no client.
      return absl::InternalError("undo and redo are applied by Process");
    case Command::kRevertToScene:
      return RevertToScene();
    case Command::KIND_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("command: no command kind is set");
}

absl::Status SimCore::ApplyEdit(const TopologyEdit& edit, CommandReply* reply,
                               Prebuilt* prebuilt) {
  const auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<sculpt::AppliedEdit> applied;
  if (prebuilt != nullptr && prebuilt->edit.has_value()) {
    if (prebuilt->edit->ok()) {
      applied = sculpt::FinishEdit(*std::move(*prebuilt->edit), *solid_);
    } else {
      applied = prebuilt->edit->status();
    }
  } else if (edit.has_bake() && edit.bake().rest_positions_size() == 0) {
    // A bake left to the server: the positions at this step (a replay of
    // such a record reaches this very step with the same bits).
    TopologyEdit stamped = edit;
    FillBake(*solid_, *stamped.mutable_bake());
    applied = sculpt::ApplyEdit(*scene_, *solid_, stamped);
  } else {
    applied = sculpt::ApplyEdit(*scene_, *solid_, edit);
  }
  if (!applied.ok()) return Rename(applied.status(), "edit", "edit");
  EditReport* r = reply->mutable_edit();
  r->set_control_cells_before(applied->cells_before);
  r->set_control_cells_after(applied->cells_after);
  r->set_control_vertices_before(applied->vertices_before);
  r->set_control_vertices_after(applied->vertices_after);
  r->set_elements_after(applied->elements_after);
  for (int64_t id : applied->transfer.dropped_loads) r->add_dropped_loads(id);
  for (int64_t id : applied->transfer.dropped_constraints) r->add_dropped_constraints(id);
  for (const std::string& name : applied->transfer.dropped_traced) r->add_dropped_traced(name);
  r->set_summary(applied->summary);
  r->set_build_ms(applied->prepare_milliseconds);
  solid_ = std::move(applied->solid);
  scene_ = std::make_shared<const Scene>(std::move(applied->scene));
  ++fields_version_;
  r->set_hold_ms(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  return absl::OkStatus();
}

absl::Status SimCore::StepOnce() {
  const absl::Status s = solid_->Step();
  if (!s.ok()) {
    paused_ = true;
    steps_remaining_ = 0;
    last_error_ = std::string(s.message());  // "step N failed: ..."
    // What a person can do about it: an undo takes its action back from the
    // solid as it is now (server/history.h), which keeps a blown-up shape.
    if (absl::StrContains(last_error_, "blew up")) {
      absl::StrAppend(&last_error_,
                      ". The session is paused; undoing the load or edit that caused it keeps "
                      "this shape, revert_to_scene (undoable) takes the session back to its scene");
    }
    return s;
  }
  if (steps_remaining_ > 0 && --steps_remaining_ == 0) paused_ = true;
  // A step went through: the state a failed step's message spoke of is gone.
  last_error_.clear();
  return s;
}

absl::Status SimCore::Replay(const persist::JournalRecord& record) {
  while (solid_->steps() < record.step()) {
    if (!WantsStep()) {
      return absl::DataLossError(absl::StrCat(
          "journal record of client ", record.client_id(), " seq ", record.seq(), " at step ",
          record.step(), ": the replayed session is paused at step ", solid_->steps()));
    }
    // A failed step is part of the history (it pauses the session).
    (void)StepOnce();
  }
  if (solid_->steps() != record.step()) {
    return absl::DataLossError(absl::StrCat("journal record of client ", record.client_id(),
                                            " seq ", record.seq(), " is for step ",
                                            record.step(), ", already past (step ",
                                            solid_->steps(), ")"));
  }
  CommandRequest request;
  request.set_client_id(record.client_id());
  request.set_seq(record.seq());
  *request.mutable_command() = record.command();
  CommandReply reply;
  const Outcome outcome = Process(request, &reply);
  save_requested_ = false;  // a replayed Save has no snapshot to write
  const CommandReply& want = record.reply();
  if (outcome == Outcome::kDuplicate || outcome == Outcome::kUnknown ||
      reply.code() != want.code() || reply.load_id() != want.load_id() ||
      reply.constraint_id() != want.constraint_id()) {
    return absl::DataLossError(absl::StrCat(
        "replaying client ", record.client_id(), " seq ", record.seq(), " at step ",
        record.step(), " gave code ", reply.code(), " (", reply.message(),
        ") where the journal has code ", want.code(), " (", want.message(), ")"));
  }
  return absl::OkStatus();
}

void SimCore::SaveTo(persist::Snapshot* snapshot) const {
  snapshot->set_step(solid_->steps());
  persist::LoopState* loop = snapshot->mutable_loop();
  loop->set_paused(paused_);
  loop->set_steps_remaining(steps_remaining_);
  loop->set_last_error(last_error_);
  loop->set_fields_version(fields_version_);
  loop->set_commands_applied(applied_);
  loop->set_commands_rejected(rejected_);
  std::vector<std::pair<int64_t, const std::string*>> owners;
  for (const auto& [id, client] : owners_) owners.emplace_back(id, &client);
  std::sort(owners.begin(), owners.end());
  for (const auto& [id, client] : owners) {
    persist::ItemOwner* o = loop->add_owners();
    o->set_id(id);
    o->set_client_id(*client);
  }
  // Clients in id order: the same state gives the same bytes.
  std::vector<const std::pair<const std::string, Client>*> sorted;
  for (const auto& entry : clients_) sorted.push_back(&entry);
  std::sort(sorted.begin(), sorted.end(),
            [](const auto* a, const auto* b) { return a->first < b->first; });
  for (const auto* entry : sorted) {
    persist::ClientAnswers* c = snapshot->add_clients();
    c->set_client_id(entry->first);
    c->set_last_seq(entry->second.last_seq);
    for (const CommandReply& r : entry->second.replies) *c->add_replies() = r;
  }
  // Edited scenes, each once, in order of first use.
  std::vector<const Scene*> table;
  auto index = [&](const std::shared_ptr<const Scene>& scene) -> int32_t {
    if (scene == original_) return -1;
    for (size_t i = 0; i < table.size(); ++i) {
      if (table[i] == scene.get()) return static_cast<int32_t>(i);
    }
    table.push_back(scene.get());
    *snapshot->add_scenes() = *scene;
    return static_cast<int32_t>(table.size() - 1);
  };
  snapshot->set_scene(index(scene_));
  history_.SaveTo(snapshot->mutable_undo_history());
}

absl::Status SimCore::RestoreFrom(const persist::Snapshot& snapshot) {
  std::vector<std::shared_ptr<const Scene>> scenes;
  for (const Scene& sc : snapshot.scenes()) scenes.push_back(std::make_shared<const Scene>(sc));
  auto scene_of = [&](int32_t i) -> absl::StatusOr<std::shared_ptr<const Scene>> {
    if (i == -1) return original_;
    if (i < 0 || i >= static_cast<int32_t>(scenes.size())) {
      return absl::DataLossError(absl::StrCat("snapshot: scene index ", i, " of ",
                                              scenes.size()));
    }
    return scenes[i];
  };
  ASSIGN_OR_RETURN(std::shared_ptr<const Scene> scene, scene_of(snapshot.scene()));
  std::shared_ptr<solid::Solid> solid = solid_;
  if (scene != scene_) {
    if (factory_ == nullptr) {
      return absl::FailedPreconditionError("snapshot of an edited solid: no factory to build it");
    }
    ASSIGN_OR_RETURN(solid, factory_(scene == original_ ? nullptr : scene.get()));
  }
  if (absl::Status s = solid->RestoreState(snapshot.solid_state()); !s.ok()) return s;
  if (solid->steps() != snapshot.step()) {
    return absl::DataLossError(absl::StrCat("snapshot says step ", snapshot.step(),
                                            ", its solid state is at step ", solid->steps()));
  }
  solid_ = std::move(solid);
  scene_ = std::move(scene);
  // (Snapshots of the old session-wide history, snapshot.undo and redo,
  // are not read: their entries are whole states, not actions.)
  history_.RestoreFrom(snapshot.undo_history());
  const persist::LoopState& loop = snapshot.loop();
  paused_ = loop.paused();
  steps_remaining_ = loop.steps_remaining();
  last_error_ = loop.last_error();
  fields_version_ = loop.fields_version();
  applied_ = loop.commands_applied();
  rejected_ = loop.commands_rejected();
  owners_.clear();
  for (const persist::ItemOwner& o : loop.owners()) owners_[o.id()] = o.client_id();
  clients_.clear();
  for (const persist::ClientAnswers& c : snapshot.clients()) {
    Client& client = clients_[c.client_id()];
    client.last_seq = c.last_seq();
    for (const CommandReply& r : c.replies()) client.replies.push_back(r);
  }
  topology_.reset();
  return absl::OkStatus();
}

std::shared_ptr<const SurfaceTopology> SimCore::Topology() {
  if (topology_ == nullptr || topology_->version != solid_->topology_version()) {
    auto t = std::make_shared<SurfaceTopology>();
    const solid::Solid::Surface& s = solid_->BoundarySurface();
    t->version = solid_->topology_version();
    t->vertex_count = static_cast<int32_t>(s.nodes.size());
    t->nodes = s.nodes;
    t->quads.reserve(4 * s.quads.size());
    for (const auto& q : s.quads) t->quads.insert(t->quads.end(), q.begin(), q.end());
    topology_ = std::move(t);
  }
  return topology_;
}

std::shared_ptr<const SurfaceSnapshot> SimCore::MakeSnapshot(bool with_fields) {
  auto snap = std::make_shared<SurfaceSnapshot>();
  snap->step = solid_->steps();
  snap->time = solid_->time();
  snap->fields_version = fields_version_;
  snap->topology = Topology();
  const Points p = solid_->SurfacePositions();
  snap->positions.assign(p.data(), p.data() + p.size());
  if (with_fields) {
    solid::Solid::SurfaceFields f = solid_->ComputeSurfaceFields();
    snap->displacement = std::move(f.displacement);
    snap->strain = std::move(f.strain);
    snap->stiffness = std::move(f.stiffness);
    snap->mass = std::move(f.mass);
  }
  return snap;
}

}  // namespace dynsolid::server
