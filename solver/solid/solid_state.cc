// The solid's exact state: SaveState writes every value the next step reads
// (positions, clock, loads, constraints, materials, drags, the integrator's
// history) in a checksummed binary record; a restore is prepared off the
// loop (PrepareState) and installed on it (RestorePreparedAtClock).
#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"
#include "solver/solid/state_codec.h"

namespace dynsolid::solid {

// ---- Exact state.

std::string Solid::SaveState() const { return JoinState(SaveStateParts()); }

std::string Solid::JoinState(const SavedState& state) {
  if (state.section == nullptr) return state.head;
  const uint64_t n = state.section->size();
  std::string out;
  out.reserve(state.head.size() + n + 16);
  out.append(state.head);
  out.append(*state.section);
  out.append(reinterpret_cast<const char*>(&n), sizeof(n));
  const uint64_t sum = CombinedChecksum(state.head_sum, state.section_sum, n);
  out.append(reinterpret_cast<const char*>(&sum), sizeof(sum));
  return out;
}

SavedState Solid::SaveStateParts() const {
  const Impl& im = *impl_;
  // The head in one buffer sized up front: the header (its payload size
  // patched at the end), the payload up to the material section.
  const models::ElementLayout& l = *im.layout;
  size_t estimate = 64 * 1024 + 8 * static_cast<size_t>(8 * p_.size());
  for (const models::ElementBlock& block : l.blocks) estimate += 8 + 40 * block.size();
  StateWriter w;
  w.out.reserve(estimate);
  w.out.assign(kStateMagic, 8);
  w.Put<uint32_t>(kStateFormatVersion);
  w.Put<uint64_t>(im.fingerprint.first);
  w.Put<uint64_t>(im.fingerprint.second);
  w.Put<uint64_t>(0);  // the payload size, patched below
  w.Put<double>(time_);
  w.Put<int64_t>(steps_);
  w.Put<int64_t>(rollbacks_);
  w.Put<int32_t>(im.substeps);
  w.Put<double>(im.omega_max);
  w.Put<double>(im.stable_step);
  w.Put<uint8_t>(im.forces_valid);
  w.Put<double>(im.last_strain_energy);
  const EnergyLedger::Values& ledger = im.ledger.values();
  w.Put<uint8_t>(ledger.rebase);
  w.Put<double>(ledger.work);
  w.Put<double>(ledger.h_min);
  w.Put<double>(ledger.peak);
  w.Put<uint8_t>(ledger.started);
  w.Matrix(p_);
  w.Matrix(p_prev_);
  if (im.probe.active() && im.f.rows() == im.probe.force().rows()) {
    w.Matrix(im.f - im.probe.force());  // contact loads are not state
  } else {
    w.Matrix(im.f);
  }
  w.Put<uint8_t>(im.has_pressure);
  if (im.has_pressure) w.Matrix(im.f_press);
  w.Matrix(im.loads.held_at());
  w.Put<uint8_t>(im.use_implicit);
  if (im.use_implicit) {
    const integrators::BackwardEuler::History& warm = im.implicit.history();
    w.Put<int32_t>(warm.steps);
    w.Matrix(warm.last);
    w.Matrix(warm.before);
  }
  w.Bytes(std::string_view(reinterpret_cast<const char*>(im.omega_fixed.data()),
                           im.omega_fixed.size()));
  w.Put<int64_t>(im.loads.next_id());
  w.Vec(im.loads.gravity());
  w.Put<uint64_t>(im.loads.point_loads().size());
  for (const auto& l : im.loads.point_loads()) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.pressures().size());
  for (const auto& l : im.loads.pressures()) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.fixes().size());
  for (const auto& c : im.loads.fixes()) {
    w.Put<int64_t>(c.id);
    w.Bytes(c.region.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.drags().size());
  for (const auto& d : im.loads.drags()) {
    w.Put<int64_t>(d.id);
    w.Put<uint8_t>(d.curve);
    w.Bytes(d.curve ? d.shape.SerializeAsString() : d.drag.SerializeAsString());
  }
  // Version 6: the environment's contacts (empty without one).
  w.Bytes(im.environment != nullptr ? im.environment->SaveState() : std::string());
  // And clay's flow laws, plastic offsets and strains (empty without).
  w.Bytes(im.plasticity != nullptr ? im.plasticity->SaveState() : std::string());
  // Element frames (warm starts).
  const models::InternalForceModel::Frames& frames = im.model->frames();
  for (const auto& f : frames) {
    w.Doubles(reinterpret_cast<const double*>(f.data()), 4 * f.size());
  }
  // The material section (CombinedChecksum), made once per material.
  SavedState saved;
  {
    std::lock_guard<std::mutex> lock(im.section_mu);
    if (im.section_epoch != im.material_epoch || im.section_bytes == nullptr) {
      StateWriter m;
      m.Put<uint64_t>(l.materials.size());
      for (const auto& array : l.materials) {
        m.Doubles(reinterpret_cast<const double*>(array.data()), 4 * array.size());
      }
      for (const models::ElementBlock& block : l.blocks) {
        m.Put<uint64_t>(block.size());
        for (int32_t e = 0; e < block.size(); ++e) m.Put<int32_t>(block.groups[block.group[e]].material);
      }
      im.section_sum = WordChecksum(m.out);
      im.section_bytes = std::make_shared<const std::string>(std::move(m.out));
      im.section_epoch = im.material_epoch;
    }
    saved.section = im.section_bytes;
    saved.section_sum = im.section_sum;
  }
  std::string& out = w.out;
  // The payload: what is here, the section and its length.
  const uint64_t payload = out.size() - kStateHeaderBytes + saved.section->size() + 8;
  std::memcpy(out.data() + kStateHeaderBytes - 8, &payload, sizeof(payload));
  saved.head_sum = WordChecksum(out);
  saved.head = std::move(out);
  return saved;
}

absl::Status Solid::RestoreState(std::string_view bytes) { return Restore(bytes, nullptr); }

absl::Status Solid::RestoreStateAtClock(std::string_view bytes, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Restore(bytes, &clock);
}

namespace {

// A saved state's loads and constraints (its gravity aside), validated and
// located again on `im`'s solid (points its current loads have are not
// searched for again). A fault is left in `r`.
LoadSet::Contents ReadLoads(StateReader& r, const Solid::Impl& im, int64_t next_id) {
  LoadSet::Contents out;
  out.next_id = next_id;
  const LoadSet::KnownPoints known = im.loads.CurrentPoints();
  const bool snap = im.settings.snap_forces_to_quadrature();
  int64_t last_id = 0;
  auto check_id = [&](int64_t id, const char* what) {
    if (r.ok() && (id <= last_id || id >= next_id)) {
      r.Fail(absl::StrCat(what, " id ", id, " out of order or not below the next id ", next_id));
    }
    last_id = std::max(last_id, id);
  };
  std::vector<LoadSet::PointLoad>& point_loads = out.point_loads;
  const int64_t n_forces = r.Count("point forces", next_id);
  for (int64_t k = 0; k < n_forces && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("point force id");
    check_id(id, "point force");
    PointForce msg;
    if (!msg.ParseFromString(r.Bytes("point force")) && r.ok()) r.Fail("point force: bad message");
    if (!r.ok()) break;
    const auto was = known.forces.find(LoadSet::KnownPoints::KeyOf(V(msg.position())));
    absl::StatusOr<MaterialLocation> at =
        was != known.forces.end() ? absl::StatusOr<MaterialLocation>(was->second.first)
                                  : im.Locate(V(msg.position()), snap);
    if (!scene::ValidatePointForce(msg, "point_force").ok() || !at.ok()) {
      r.Fail(absl::StrCat("point force ", id, " is invalid for this solid"));
      break;
    }
    // The control row here, off the loop, unless the solid has it.
    std::shared_ptr<const LoadSet::ControlWeights> row =
        was != known.forces.end() && was->second.second != nullptr
            ? was->second.second
            : std::make_shared<const LoadSet::ControlWeights>(im.ControlRowAt(*at));
    point_loads.push_back({id, std::move(msg), *at, std::move(row)});
  }
  last_id = 0;
  std::vector<LoadSet::PressureLoad>& pressures = out.pressures;
  const int64_t n_pressures = r.Count("pressures", next_id);
  for (int64_t k = 0; k < n_pressures && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("pressure id");
    check_id(id, "pressure");
    Pressure msg;
    if (!msg.ParseFromString(r.Bytes("pressure")) && r.ok()) r.Fail("pressure: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> quads;
    if (scene::ValidatePressure(msg, "pressure").ok() &&
        im.CheckControlCells(msg.region(), "pressure.region").ok()) {
      quads = im.SelectQuads(msg.region());
    }
    if (quads.empty()) {
      r.Fail(absl::StrCat("pressure ", id, " is invalid for this solid"));
      break;
    }
    pressures.push_back({id, std::move(msg), std::move(quads)});
  }
  last_id = 0;
  std::vector<LoadSet::FixConstraint>& fixes = out.fixes;
  const int64_t n_fixes = r.Count("fixed regions", next_id);
  for (int64_t k = 0; k < n_fixes && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("fixed region id");
    check_id(id, "fixed region");
    Region region;
    if (!region.ParseFromString(r.Bytes("fixed region")) && r.ok()) r.Fail("fixed region: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> points;
    if (scene::ValidateValues(region, "region").ok() && scene::ValidateRegion(region, "region").ok() &&
        im.CheckControlCells(region, "region").ok()) {
      points = im.SelectControlPoints(region);
    }
    if (points.empty()) {
      r.Fail(absl::StrCat("fixed region ", id, " is invalid for this solid"));
      break;
    }
    fixes.push_back({id, std::move(region), std::move(points)});
  }
  last_id = 0;
  std::vector<LoadSet::DragLoad>& drags = out.drags;
  const int64_t n_drags = r.Count("drags", next_id);
  for (int64_t k = 0; k < n_drags && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("drag id");
    check_id(id, "drag");
    const bool curve = r.Get<uint8_t>("drag kind") != 0;
    const std::string bytes = r.Bytes("drag");
    if (!r.ok()) break;
    absl::StatusOr<LoadSet::DragLoad> load = absl::InvalidArgumentError("bad message");
    if (curve) {
      CurveDrag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeCurve(msg, &known);
    } else {
      Drag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeDrag(msg, &known);
    }
    if (!load.ok()) {
      r.Fail(absl::StrCat("drag ", id, " is invalid for this solid: ", load.status().message()));
      break;
    }
    load->id = id;
    drags.push_back(*std::move(load));
  }
  return out;
}

}  // namespace

namespace {

// What the payload holds before its loads that is not PreparedState's own.
struct MotionRest {
  Points hold;                // held positions
  bool saved_pressure = false;  // follower forces were saved
  int64_t next_id = 0;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
};

// The clock, the stable step, the energy ledger, the positions and carried
// forces, the integrator's warm start and the stable-step fixed set, into
// `out`; checked against `im`'s solid of nc control points.
MotionRest ReadMotion(StateReader& r, const Solid::Impl& im, int64_t nc,
                      Solid::PreparedState& out) {
  MotionRest rest;
  out.time = r.Get<double>("time");
  out.steps = r.Get<int64_t>("steps");
  out.rollbacks = r.Get<int64_t>("rollbacks");
  out.substeps = r.Get<int32_t>("substeps");
  out.omega = r.Get<double>("omega_max");
  out.stable = r.Get<double>("stable_step");
  out.forces_valid = r.Get<uint8_t>("forces_valid") != 0;
  out.strain = r.Get<double>("strain energy");
  out.ledger.rebase = r.Get<uint8_t>("ledger rebase") != 0;
  out.ledger.work = r.Get<double>("ledger");
  out.ledger.h_min = r.Get<double>("ledger");
  out.ledger.peak = r.Get<double>("ledger");
  out.ledger.started = r.Get<uint8_t>("ledger") != 0;
  out.p = r.Matrix("p", nc);
  out.p_prev = r.Matrix("p_prev", nc);
  out.f = r.Matrix("forces", nc);
  rest.saved_pressure = r.Get<uint8_t>("pressure flag") != 0;
  if (rest.saved_pressure) out.f_press = r.Matrix("pressure forces", nc);
  rest.hold = r.Matrix("held positions", nc);
  const bool saved_implicit = r.Get<uint8_t>("implicit flag") != 0;
  if (r.ok() && saved_implicit != im.use_implicit) {
    r.Fail(absl::StrCat("saved with ", saved_implicit ? "backward Euler" : "central difference",
                        ", this solid steps with the other integrator"));
  }
  if (saved_implicit) {
    out.warm.steps = r.Get<int32_t>("backward Euler warm start");
    out.warm.last = r.Matrix("backward Euler warm start", nc);
    out.warm.before = r.Matrix("backward Euler warm start", nc);
    if (r.ok() && (out.warm.steps < 0 || out.warm.steps > 2)) {
      r.Fail(absl::StrCat("backward Euler warm start over ", out.warm.steps, " steps (0 to 2)"));
    }
  }
  out.omega_fixed_bytes = r.Bytes("stable-step fixed set");
  if (r.ok() && static_cast<int64_t>(out.omega_fixed_bytes.size()) != nc) {
    r.Fail(absl::StrCat("stable-step fixed set: ", out.omega_fixed_bytes.size(),
                        " entries, expected ", nc));
  }
  rest.next_id = r.Get<int64_t>("next id");
  rest.gravity = r.Vec("gravity");
  if (r.ok() && (out.substeps < 1 || out.substeps > std::max(1, im.settings.max_substeps()))) {
    r.Fail(absl::StrCat("substeps ", out.substeps, " out of range"));
  }
  return rest;
}

// A saved material: its sample arrays and each element's array.
struct SavedMaterial {
  std::vector<std::vector<models::MaterialPoint>> arrays;
  std::array<std::vector<int32_t>, fem::kElementKinds> element_array;
  // True when layout `l` holds exactly this material.
  bool Is(const models::ElementLayout& l) const {
    bool same = arrays.size() == l.materials.size();
    for (size_t k = 0; same && k < arrays.size(); ++k) {
      same = arrays[k].size() == l.materials[k].size() &&
             std::memcmp(arrays[k].data(), l.materials[k].data(),
                         arrays[k].size() * sizeof(models::MaterialPoint)) == 0;
    }
    for (int kind = 0; kind < fem::kElementKinds && same; ++kind) {
      const models::ElementBlock& block = l.blocks[kind];
      same = static_cast<int64_t>(element_array[kind].size()) == block.size();
      for (int32_t e = 0; e < block.size() && same; ++e) {
        same = element_array[kind][e] == block.groups[block.group[e]].material;
      }
    }
    return same;
  }
};

// The material section and the element frames (version 5 and later: the
// frames first, then the section and its length), checked against the
// current layout `cur`; the payload must end there.
void ReadMaterialAndFrames(StateReader& r, const StateHeader& header,
                           const models::ElementLayout& cur, SavedMaterial& material,
                           models::InternalForceModel::Frames& frames) {
  int64_t max_arrays = 0;
  for (const models::ElementBlock& block : cur.blocks) max_arrays += block.size();
  auto read_materials = [&] {
    const int64_t n_arrays = r.Count("material arrays", max_arrays);
    std::vector<std::vector<models::MaterialPoint>>& arrays = material.arrays;
    arrays.resize(r.ok() ? n_arrays : 0);
    for (int64_t k = 0; k < n_arrays && r.ok(); ++k) {
      const std::vector<double> v = r.Doubles("material array");
      if (!r.ok()) break;
      if (v.size() % 4 != 0) {
        r.Fail("material array: not whole samples");
        break;
      }
      arrays[k].resize(v.size() / 4);
      if (!v.empty()) {
        std::memcpy(static_cast<void*>(arrays[k].data()), v.data(), v.size() * sizeof(double));
      }
    }
    for (int kind = 0; kind < fem::kElementKinds && r.ok(); ++kind) {
      const models::ElementBlock& block = cur.blocks[kind];
      const int64_t count = r.Count("elements", max_arrays);
      if (r.ok() && count != block.size()) {
        r.Fail(absl::StrCat("material of kind ", kind, ": ", count, " elements, the solid has ",
                            block.size()));
      }
      std::vector<int32_t>& element_array = material.element_array[kind];
      element_array.resize(r.ok() ? count : 0);
      for (int64_t e = 0; e < count && r.ok(); ++e) {
        const int32_t a = r.Get<int32_t>("element material");
        if (r.ok() && (a < 0 || a >= n_arrays ||
                       static_cast<int>(arrays[a].size()) != cur.tables[kind].points)) {
          r.Fail(absl::StrCat("element ", e, " of kind ", kind, ": bad material array ", a));
        }
        element_array[e] = a;
      }
    }
  };
  auto read_frames = [&] {
    for (int kind = 0; kind < fem::kElementKinds && r.ok(); ++kind) {
      const std::vector<double> v = r.Doubles("frames", 4 * int64_t{cur.blocks[kind].size()});
      if (!r.ok()) break;
      frames[kind].resize(cur.blocks[kind].size());
      if (!v.empty()) {
        std::memcpy(static_cast<void*>(frames[kind].data()), v.data(), v.size() * sizeof(double));
      }
    }
  };
  if (header.version >= 5) {
    read_frames();
    if (r.ok() && kStateHeaderBytes + r.pos() != header.section_at) {
      r.Fail(absl::StrCat("the material section starts at byte ",
                          header.section_at - kStateHeaderBytes, ", the frames end at ", r.pos()));
    }
    read_materials();
    if (r.ok() && r.Get<uint64_t>("material section length") != header.section_bytes) {
      r.Fail("material section length");
    }
  } else {
    read_materials();
    read_frames();
  }
  if (r.ok() && !r.at_end()) r.Fail(absl::StrCat("unexpected bytes after byte ", r.pos()));
}

// The material of a state into `out`: taken as it is when it is the
// current one, taken back when it is the one the current one replaced, else
// built (on a pool of its own: the solid's may be stepping); then, for
// backward Euler, the Setup for the restored fixed set, sub-steps, mass and
// K0 (made here, off the loop when a server prepares an undo). h: the
// solid's time step.
absl::Status PrepareMaterial(const Solid::Impl& im, double h, const SavedMaterial& saved,
                             Solid::PreparedState& out) {
  const models::ElementLayout& cur = *im.layout;
  auto material_is = [&](const models::ElementLayout& l) { return saved.Is(l); };
  const bool same_material = material_is(cur);
  if (!same_material) {
    if (std::optional<Solid::Impl::RetiredMaterial> r = im.TakeRetired(material_is)) {
      out.build = std::move(r->build);
      out.k0 = std::move(r->k0);
      out.k0_cells = std::move(r->k0_cells);
      out.taken_back = true;
    }
  }
  if (!same_material && !out.taken_back) {
    auto layout = std::make_unique<models::ElementLayout>(
        models::RelayoutMaterials(cur, im.rest_nodes, [&](int kind, int32_t e) {
          return &saved.arrays[saved.element_array[kind][e]];
        }));
    out.pool = std::make_unique<WorkerPool>(1);
    ASSIGN_OR_RETURN(out.build, im.BuildMaterial(std::move(layout), /*reuse=*/true, out.pool.get()));
    if (im.use_implicit) {
      out.k0 = im.StiffnessMatrix(*out.build->layout, *out.build->corotational, *out.pool,
                                  &out.k0_cells, out.build->k_cells.get());
    }
  }
  if (im.use_implicit) {
    const std::optional<MaterialBuild>& build = out.build;
    const SparseMatrix& mt = build ? build->mt : im.mt;
    const bool damped = build ? build->has_damping : im.has_damping;
    const SparseMatrix& dt = build ? build->dt : im.dt;
    if (build) build->corotational->SetSinglePrecisionLinearized(im.SinglePrecisionLinearized());
    out.implicit_setup = integrators::BackwardEuler::Prepare(
        mt, damped ? &dt : nullptr, h / out.substeps, out.loads.FixedFlags(),
        build ? &out.k0 : &im.k0);
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareStateView(
    std::string_view bytes) const {
  static_assert(sizeof(models::MaterialPoint) == 4 * sizeof(double));
  const Impl& im = *impl_;
  const int64_t nc = p_.rows();
  ASSIGN_OR_RETURN(const StateHeader header, ReadStateHeader(bytes, kStateFormatVersion));
  if (header.fingerprint != im.fingerprint) {
    return absl::InvalidArgumentError(
        "solid state: saved from a different scene or discretization (fingerprint mismatch); "
        "restore into a solid created from the same scene and levels");
  }

  // Parse and check everything before changing anything.
  auto out = std::make_shared<PreparedState>();
  out->material_epoch = im.material_epoch;
  StateReader r(header.payload);
  MotionRest rest = ReadMotion(r, im, nc, *out);
  RETURN_IF_ERROR(r.status());

  // Loads and constraints: parsed, validated and located again.
  LoadSet::Contents loads = ReadLoads(r, im, rest.next_id);
  RETURN_IF_ERROR(r.status());
  loads.gravity = rest.gravity;
  out->loads = LoadSet(std::move(loads), std::move(rest.hold));
  if (rest.saved_pressure != (!(out->loads.pressures().empty() && out->loads.drags().empty()) ||
                              im.environment != nullptr)) {
    r.Fail("follower forces without pressures, drags or an environment");
  }
  // Version 6: the environment's contacts and clay's state.
  if (header.version >= 6 && r.ok()) {
    const std::string env = r.Bytes("environment");
    const std::string clay = r.Bytes("plasticity");
    if (r.ok()) {
      if (absl::Status st = im.ParseParts(env, clay, out->touches, out->plastic); !st.ok()) {
        r.Fail(std::string(st.message()));
      }
    }
  }
  RETURN_IF_ERROR(r.status());

  SavedMaterial material;
  ReadMaterialAndFrames(r, header, *im.layout, material, out->frames);
  RETURN_IF_ERROR(r.status());
  RETURN_IF_ERROR(PrepareMaterial(im, h_, material, *out));
  return out;
}

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareState(
    std::string bytes) const {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> out, PrepareStateView(bytes));
  out->bytes = std::move(bytes);
  return out;
}

absl::Status Solid::Restore(std::string_view bytes, const std::pair<double, int64_t>* clock) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> state, PrepareStateView(bytes));
  return Install(*state, clock);
}

absl::Status Solid::RestorePreparedAtClock(PreparedState& state, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Install(state, &clock);
}

absl::Status Solid::Install(PreparedState& prepared, const std::pair<double, int64_t>* clock) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedState> again;
  PreparedState* ps = &prepared;
  if (prepared.material_epoch != im.material_epoch || prepared.used) {
    // Prepared against a material that has changed since: again, now.
    if (prepared.bytes.empty()) {
      return absl::InternalError("solid state: prepared for another material, bytes not kept");
    }
    ASSIGN_OR_RETURN(again, PrepareStateView(prepared.bytes));
    ps = again.get();
  }
  PreparedState& s = *ps;
  s.used = true;
  // Nothing can fail from here on.
  if (s.build) {
    s.build->model->set_pool(*im.pool);
    im.InstallMaterial(*std::move(s.build));
    if (im.use_implicit) {
      im.k0 = std::move(s.k0);
      im.k0_cells = std::move(s.k0_cells);
    }
    total_mass_ = SumOfValues(im.mt);
    ReportMaterial();
    if (s.taken_back) ++report_.materials_taken_back;
  }
  im.model->set_frames(s.frames);
  im.loads = std::move(s.loads);
  im.InstallParts(std::move(s.touches), std::move(s.plastic));
  im.RebuildConstantLoads();
  im.RebuildPressure();
  if (im.has_pressure) im.f_press = std::move(s.f_press);
  im.omega_fixed.assign(s.omega_fixed_bytes.begin(), s.omega_fixed_bytes.end());
  im.omega_max = s.omega;
  im.stable_step = s.stable;
  im.fixed = im.loads.FixedFlags();
  im.SetSubsteps(s.substeps, h_, &s.implicit_setup);
  if (im.use_implicit) im.implicit.set_history(std::move(s.warm));  // checked above
  p_ = std::move(s.p);
  p_prev_ = std::move(s.p_prev);
  im.f = std::move(s.f);
  im.forces_valid = s.forces_valid;
  im.probe.Clear();  // the restored `f` carries no contact load
  ++im.contact.epoch;      // and its fixed set or material may differ
  im.loads_changed = true;  // not saved: recomputing the loads changes no bit
  im.last_strain_energy = s.strain;
  im.ledger.set_values(s.ledger);
  time_ = clock != nullptr ? clock->first : s.time;
  steps_ = clock != nullptr ? clock->second : s.steps;
  rollbacks_ = s.rollbacks;
  report_.substeps = s.substeps;
  report_.omega_max = s.omega;
  report_.stable_step = s.stable;
  report_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  report_.gravity = im.loads.has_gravity();
  report_.fixed_control_points =
      static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  last_step_ = StepStats();
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
