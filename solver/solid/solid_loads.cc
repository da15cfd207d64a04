// Loads and constraints of a live solid (solid.h "Runtime edits"): point
// forces, follower pressures, gravity, drags, fixed regions, and the
// selections of regions they are built from.
#include <algorithm>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/load_bounds.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {

void Solid::Impl::RebuildConstantLoads() {
  loads.RebuildConstantForces(
      rest_control.rows(), [this](const MaterialLocation& at) { return ControlRowAt(at); },
      [this]() -> const Eigen::VectorXd& { return GravityMass(); });
}

const Eigen::VectorXd& Solid::Impl::GravityMass() {
  // A^T w = A^T M 1 = A^T M A 1 = Mt 1: the nodes' basis functions sum to
  // one (so M 1 = w), and so do the rows of A (subdivision and the
  // pyramids' virtual nodes are affine combinations). One product with the
  // control mass matrix instead of an integration over every element.
  if (gravity_mass.size() != mt.rows()) {
    gravity_mass = mt * Eigen::VectorXd::Ones(mt.cols());
  }
  return gravity_mass;
}

void Solid::Impl::RebuildPressure() {
  // The follower loads: pressures and drag springs (forces that depend on
  // the positions; work counted trapezoidally in the ledger).
  has_pressure = !loads.pressures().empty() || !loads.drags().empty() || environment != nullptr;
  pressure.Rebuild(surface->quads, surface_rows, loads.pressures());
  if (has_pressure) {
    const int64_t nc = rest_control.rows();
    f_press.setZero(nc, 3);
    f_press_next.setZero(nc, 3);
  }
}

void Solid::Impl::PressureForces(const Points& p, Points& out) {
  pressure.Forces(p, out);
  loads.AddDragForces(p, out);
}

std::vector<int32_t> Solid::Impl::SelectControlPoints(const Region& r) const {
  const mesh::CellComplex& control = d->control();
  std::vector<int32_t> out;
  for (int32_t i = 0; i < rest_control.rows(); ++i) {
    if (InShape(r, rest_control.row(i).transpose())) out.push_back(i);
  }
  for (int32_t c : r.control_cells()) {
    for (int32_t v : control.cell_vertices(c)) out.push_back(v);
  }
  for (int32_t v : r.control_points()) out.push_back(v);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::vector<int32_t> Solid::Impl::SelectQuads(const Region& r) const {
  std::vector<int32_t> out;
  const std::vector<int32_t>& cc = d->hierarchy.control_cell;
  for (size_t q = 0; q < quad_cell.size(); ++q) {
    const int32_t control_cell = cc.empty() ? quad_cell[q] : cc[quad_cell[q]];
    if (InRegion(r, quad_centroid[q], control_cell)) out.push_back(static_cast<int32_t>(q));
  }
  return out;
}

absl::Status Solid::Impl::CheckControlCells(const Region& r, std::string_view field) const {
  const int32_t n = d->control().num_cells();
  for (int i = 0; i < r.control_cells_size(); ++i) {
    if (r.control_cells(i) >= n) {
      return absl::InvalidArgumentError(absl::StrCat(
          A(field), ".control_cells[", i, "] (", r.control_cells(i),
          ") must be less than the number of control cells (", n, ")"));
    }
  }
  const int32_t nv = d->control().num_vertices();
  for (int i = 0; i < r.control_points_size(); ++i) {
    if (r.control_points(i) >= nv) {
      return absl::InvalidArgumentError(absl::StrCat(
          A(field), ".control_points[", i, "] (", r.control_points(i),
          ") must be less than the number of control points (", nv, ")"));
    }
  }
  return absl::OkStatus();
}


void Solid::ApplyFixed() {
  Impl& im = *impl_;
  im.fixed = im.loads.FixedFlags();
  report_.fixed_control_points =
      static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  ++im.contact.epoch;  // the contact stiffness depends on the fixed set
  im.SetSubsteps(im.substeps, h_);
}

// ---- Loads.

LoadScale Solid::load_scale() const {
  return ScaleOf(impl_->rest_control, *impl_->layout, total_mass_, rest_volume_);
}

absl::StatusOr<int64_t> Solid::AddPointForce(const PointForce& f) {
  Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidatePointForce(f, "point_force"));
  RETURN_IF_ERROR(CheckForce(load_scale(), V(f.force()).stableNorm(), "point_force.force"));
  absl::StatusOr<MaterialLocation> at =
      im.Locate(V(f.position()), im.settings.snap_forces_to_quadrature());
  if (!at.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("point_force.position: ", at.status().message()));
  }
  const int64_t id = im.loads.Add(LoadSet::PointLoad{0, f, *at});
  im.RebuildConstantLoads();
  im.LoadsChanged();
  report_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  return id;
}

absl::StatusOr<int64_t> Solid::AddPressure(const Pressure& p) {
  Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidatePressure(p, "pressure"));
  RETURN_IF_ERROR(CheckPressure(load_scale(), p.pascals(), "pressure.pascals"));
  RETURN_IF_ERROR(im.CheckControlCells(p.region(), "pressure.region"));
  std::vector<int32_t> quads = im.SelectQuads(p.region());
  if (quads.empty()) {
    return absl::InvalidArgumentError(
        "pressure.region selects no boundary face (no face has its rest centroid in the region "
        "or its cell in control_cells)");
  }
  const int64_t id = im.loads.Add(LoadSet::PressureLoad{0, p, std::move(quads)});
  im.RebuildPressure();
  im.LoadsChanged();
  return id;
}

absl::Status Solid::SetGravity(const Vec3& g) {
  Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidateValues(g, "gravity"));
  RETURN_IF_ERROR(CheckGravity(load_scale(), V(g).stableNorm(), "gravity"));
  im.loads.SetGravity(V(g));
  im.RebuildConstantLoads();
  im.LoadsChanged();
  report_.gravity = im.loads.has_gravity();
  return absl::OkStatus();
}

absl::Status Solid::RemoveLoad(int64_t id) {
  Impl& im = *impl_;
  switch (im.loads.RemoveLoad(id)) {
    case LoadSet::Kind::kPointForce:
      im.RebuildConstantLoads();
      report_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
      break;
    case LoadSet::Kind::kPressure:
    case LoadSet::Kind::kDrag:
      im.RebuildPressure();
      break;
    case LoadSet::Kind::kNone:
      return absl::NotFoundError(absl::StrCat("load id ", id, " not found (active ",
                                              im.loads.DescribeLoadIds(), ")"));
  }
  im.LoadsChanged();
  return absl::OkStatus();
}

std::vector<int64_t> Solid::load_ids() const { return impl_->loads.LoadIds(); }

std::vector<int64_t> Solid::constraint_ids() const { return impl_->loads.ConstraintIds(); }

Eigen::Vector3d Solid::gravity() const { return impl_->loads.gravity(); }

std::vector<Solid::LoadInfo> Solid::ActiveLoads() const {
  const Impl& im = *impl_;
  std::vector<LoadInfo> out;
  std::vector<double> shape;
  for (const LoadSet::PointLoad& load : im.loads.point_loads()) {
    LoadInfo info;
    info.id = load.id;
    info.kind = LoadInfo::Kind::kPointForce;
    info.material_points.push_back(V(load.msg.position()));
    info.positions.push_back(im.PositionAt(load.at, p_, shape));  // where it acts
    info.force = V(load.msg.force());
    out.push_back(std::move(info));
  }
  for (const LoadSet::PressureLoad& load : im.loads.pressures()) {
    LoadInfo info;
    info.id = load.id;
    info.kind = LoadInfo::Kind::kPressure;
    info.pascals = load.msg.pascals();
    info.region = load.msg.region();
    info.quads = load.quads;
    out.push_back(std::move(info));
  }
  for (const LoadSet::DragLoad& load : im.loads.drags()) {
    LoadInfo info;
    info.id = load.id;
    info.kind = load.curve ? LoadInfo::Kind::kCurve : LoadInfo::Kind::kDrag;
    info.material_points = load.material;
    for (const auto& row : load.rows) {
      Eigen::Vector3d x = Eigen::Vector3d::Zero();
      for (const auto& [i, w] : row) x += w * p_.row(i).transpose();
      info.positions.push_back(x);
    }
    info.targets = load.targets;
    info.stiffness = load.stiffness;
    if (load.curve) info.curve = load.shape;
    out.push_back(std::move(info));
  }
  std::sort(out.begin(), out.end(),
            [](const LoadInfo& a, const LoadInfo& b) { return a.id < b.id; });
  return out;
}

std::vector<Solid::ConstraintInfo> Solid::ActiveConstraints() const {
  std::vector<ConstraintInfo> out;
  for (const LoadSet::FixConstraint& c : impl_->loads.fixes()) {
    out.push_back({c.id, c.region, c.points});
  }
  std::sort(out.begin(), out.end(),
            [](const ConstraintInfo& a, const ConstraintInfo& b) { return a.id < b.id; });
  return out;
}

// ---- Constraints.

absl::StatusOr<int64_t> Solid::FixRegion(const Region& r) {
  Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidateValues(r, "region"));
  RETURN_IF_ERROR(scene::ValidateNonEmptyRegion(r, "region"));
  RETURN_IF_ERROR(im.CheckControlCells(r, "region"));
  std::vector<int32_t> points = im.SelectControlPoints(r);
  if (points.empty()) {
    return absl::InvalidArgumentError(
        "region selects no control point (no control point's rest position lies in it)");
  }
  // Newly held points stay where they are, with zero velocity.
  std::vector<int32_t> newly_held;
  const int64_t id = im.loads.AddFix(r, std::move(points), p_, &newly_held);
  for (int32_t i : newly_held) p_prev_.row(i) = p_.row(i);
  ApplyFixed();
  im.forces_valid = false;
  im.ledger.RequestRebase();
  return id;
}

absl::Status Solid::Unfix(int64_t constraint_id) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedUnfix> prepared, PrepareUnfix(constraint_id));
  return ApplyUnfix(*prepared);
}

absl::StatusOr<std::shared_ptr<Solid::PreparedUnfix>> Solid::PrepareUnfix(
    int64_t constraint_id) const {
  const Impl& im = *impl_;
  if (im.loads.FindFix(constraint_id) == nullptr) {
    return absl::NotFoundError(absl::StrCat("constraint id ", constraint_id,
                                            " not found (active fixed regions: ",
                                            im.loads.DescribeConstraintIds(), ")"));
  }
  auto out = std::make_shared<PreparedUnfix>();
  out->constraint_id = constraint_id;
  out->made_for = im.PreparedForNow();
  out->count = im.loads.CountsWithout(constraint_id);
  // The stable-step estimate holds while every point it was made with
  // fixed stays fixed; otherwise estimate again, on a model of this call's
  // own (the live one may be stepping on another thread).
  for (size_t i = 0; i < out->count.size(); ++i) {
    out->reestimate |= im.omega_fixed[i] && out->count[i] == 0;
  }
  out->omega = im.omega_max;
  out->substeps = im.substeps;
  out->new_fixed.resize(out->count.size());
  for (size_t i = 0; i < out->count.size(); ++i) out->new_fixed[i] = out->count[i] > 0 ? 1 : 0;
  if (out->reestimate) {
    WorkerPool pool(1);
    const std::shared_ptr<const models::ElementLayout> layout = im.layout;  // kept for `own`
    std::unique_ptr<models::InternalForceModel> own = im.ModelCopy(*layout, *im.model, pool);
    out->omega = im.EstimateOmegaMax(*own, im.mt, out->new_fixed, nullptr, im.cell_model.get(),
                                     &pool);
    if (!im.use_implicit) {
      out->substeps = std::max(im.substeps, im.SubstepsFor(out->omega));
      if (out->substeps > im.settings.max_substeps()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "constraint id ", constraint_id, ": without it the solid needs ", out->substeps,
            " explicit sub-steps (stable step ", 2.0 / out->omega,
            " s) but solver.max_substeps is ", im.settings.max_substeps()));
      }
    }
  }
  return out;
}

absl::Status Solid::ApplyUnfix(PreparedUnfix& prepared) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedUnfix> again;
  PreparedUnfix* p = &prepared;
  if (prepared.used || prepared.made_for != im.PreparedForNow()) {
    // Prepared for a solid that has changed since: again, now.
    ASSIGN_OR_RETURN(again, PrepareUnfix(prepared.constraint_id));
    p = again.get();
  }
  p->used = true;
  im.loads.RemoveFix(p->constraint_id);  // the counts p->count has
  if (p->reestimate) {
    im.omega_max = p->omega;
    im.stable_step = p->omega > 0 ? 2.0 / p->omega : INFINITY;
    im.omega_fixed = p->new_fixed;
    report_.omega_max = im.omega_max;
    report_.stable_step = im.stable_step;
    if (p->substeps != im.substeps) {
      const double old_h = im.h_sub;
      im.substeps = p->substeps;
      im.h_sub = h_ / p->substeps;
      p_prev_ = p_ - (im.h_sub / old_h) * (p_ - p_prev_);  // keep the velocity
      report_.substeps = p->substeps;
    }
  }
  ApplyFixed();
  im.forces_valid = false;
  im.ledger.RequestRebase();
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
