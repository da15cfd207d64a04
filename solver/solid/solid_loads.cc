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
  has_const_force = !point_loads.empty() || gravity.squaredNorm() > 0;
  if (!has_const_force) {
    f_const.resize(0, 3);
    return;
  }
  // f = sum over the loads, in order, of their control rows times their
  // forces (A^T N F, N the shape values at the load's material point): a
  // function of the load list alone, made without touching the solid's
  // other nodes (a point force added or removed holds the loop for this).
  f_const = Points::Zero(rest_control.rows(), 3);
  for (PointLoad& load : point_loads) {
    if (load.row == nullptr) load.row = std::make_shared<const ControlWeights>(ControlRowAt(load.at));
    const Eigen::RowVector3d force = V(load.msg.force()).transpose();
    for (const auto& [c, w] : *load.row) f_const.row(c) += w * force;
  }
  if (gravity.squaredNorm() > 0) {
    // Body force mu g: f = A^T w g^T with w_i = int mu N_i dV, kept per
    // material (GravityMass), so that a new force or gravity costs no
    // integration over the solid.
    f_const += GravityMass() * gravity.transpose();
  }
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
  has_pressure = !pressures.empty() || !drags.empty() || environment != nullptr;
  quad_pascals.assign(quad_cell.size(), 0.0);
  for (const PressureLoad& load : pressures) {
    for (int32_t q : load.quads) quad_pascals[q] += load.msg.pascals();
  }
  pressed.clear();
  for (size_t q = 0; q < quad_pascals.size(); ++q) {
    if (quad_pascals[q] != 0) pressed.push_back(static_cast<int32_t>(q));
  }
  // The pressed quads' vertices (ascending) and their rows of S: the step
  // evaluates the pressure there, not over the whole surface.
  std::vector<int32_t> vertices;
  for (int32_t q : pressed) {
    for (int32_t v : surface->quads[q]) vertices.push_back(v);
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  pressed_corners.clear();
  for (int32_t q : pressed) {
    std::array<int32_t, 4> local;
    for (int k = 0; k < 4; ++k) {
      local[k] = static_cast<int32_t>(
          std::lower_bound(vertices.begin(), vertices.end(), surface->quads[q][k]) - vertices.begin());
    }
    pressed_corners.push_back(local);
  }
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (size_t i = 0; i < vertices.size(); ++i) {
    for (SparseMatrix::InnerIterator it(surface_rows, vertices[i]); it; ++it) {
      t.emplace_back(static_cast<int32_t>(i), static_cast<int32_t>(it.col()), it.value());
    }
  }
  pressed_rows.resize(static_cast<Eigen::Index>(vertices.size()), surface_rows.cols());
  pressed_rows.setFromTriplets(t.begin(), t.end());
  pressed_rows.makeCompressed();
  const int64_t nc = rest_control.rows(), ns = static_cast<int64_t>(vertices.size());
  if (has_pressure) {
    surf_x.setZero(ns, 3);
    surf_f.setZero(ns, 3);
    f_press.setZero(nc, 3);
    f_press_next.setZero(nc, 3);
  }
}

// out = S^T f_s with f_s the consistent nodal forces of the pressure on the
// surface quads at the current surface positions x_s = S p (S: the surface
// rows of A). Each quad is a bilinear patch x(u, v) = sum N_i x_i over its
// loop (a boundary face of a linear or pyramid element, so the element's own
// interpolation): f_i = P int N_i (x_u x x_v) du dv, exact with 2 x 2 Gauss
// points (the integrand has degree 2 in u and in v). x_u x x_v follows the
// outward loop, so P > 0 pushes outward. The forces sum to P times the
// quad's vector area; over a closed surface to zero.
void Solid::Impl::PressureForces(const Points& p, Points& out) {
  if (pressed.empty()) {
    out.setZero(p.rows(), 3);
    AddDragForces(p, out);
    return;
  }
  surf_x.noalias() = pressed_rows * p;
  surf_f.setZero();
  const double g0 = 0.5 - 0.5 / std::sqrt(3.0), g1 = 0.5 + 0.5 / std::sqrt(3.0);
  const double gp[2] = {g0, g1};
  for (size_t j = 0; j < pressed.size(); ++j) {
    const int32_t q = pressed[j];
    const std::array<int32_t, 4>& v = pressed_corners[j];
    const Eigen::Vector3d x0 = surf_x.row(v[0]).transpose(), x1 = surf_x.row(v[1]).transpose(),
                          x2 = surf_x.row(v[2]).transpose(), x3 = surf_x.row(v[3]).transpose();
    Eigen::Vector3d fn[4] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                             Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
    for (double u : gp) {
      for (double w : gp) {
        // N0 = (1-u)(1-w), N1 = u(1-w), N2 = u w, N3 = (1-u) w.
        const Eigen::Vector3d xu = (1 - w) * (x1 - x0) + w * (x2 - x3);
        const Eigen::Vector3d xw = (1 - u) * (x3 - x0) + u * (x2 - x1);
        const Eigen::Vector3d n = 0.25 * xu.cross(xw);  // Gauss weights 1/2 x 1/2
        fn[0] += ((1 - u) * (1 - w)) * n;
        fn[1] += (u * (1 - w)) * n;
        fn[2] += (u * w) * n;
        fn[3] += ((1 - u) * w) * n;
      }
    }
    const double pa = quad_pascals[q];
    for (int k = 0; k < 4; ++k) surf_f.row(v[k]) += (pa * fn[k]).transpose();
  }
  out.noalias() = pressed_rows.transpose() * surf_f;
  AddDragForces(p, out);
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
  for (size_t i = 0; i < im.fixed.size(); ++i) im.fixed[i] = im.fix_count[i] > 0 ? 1 : 0;
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
  const int64_t id = im.next_id++;
  im.point_loads.push_back({id, f, *at});
  im.RebuildConstantLoads();
  im.LoadsChanged();
  report_.point_forces = static_cast<int32_t>(im.point_loads.size());
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
  const int64_t id = im.next_id++;
  im.pressures.push_back({id, p, std::move(quads)});
  im.RebuildPressure();
  im.LoadsChanged();
  return id;
}

absl::Status Solid::SetGravity(const Vec3& g) {
  Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidateValues(g, "gravity"));
  RETURN_IF_ERROR(CheckGravity(load_scale(), V(g).stableNorm(), "gravity"));
  im.gravity = V(g);
  im.RebuildConstantLoads();
  im.LoadsChanged();
  report_.gravity = im.gravity.squaredNorm() > 0;
  return absl::OkStatus();
}

namespace {
template <typename T>
std::string IdList(const std::vector<T>& items) {
  if (items.empty()) return "none";
  std::string out;
  for (const T& x : items) absl::StrAppend(&out, out.empty() ? "" : ", ", x.id);
  return out;
}
}  // namespace

absl::Status Solid::RemoveLoad(int64_t id) {
  Impl& im = *impl_;
  auto pf = std::find_if(im.point_loads.begin(), im.point_loads.end(),
                         [id](const Impl::PointLoad& l) { return l.id == id; });
  if (pf != im.point_loads.end()) {
    im.point_loads.erase(pf);
    im.RebuildConstantLoads();
    im.LoadsChanged();
    report_.point_forces = static_cast<int32_t>(im.point_loads.size());
    return absl::OkStatus();
  }
  auto pr = std::find_if(im.pressures.begin(), im.pressures.end(),
                         [id](const Impl::PressureLoad& l) { return l.id == id; });
  if (pr != im.pressures.end()) {
    im.pressures.erase(pr);
    im.RebuildPressure();
    im.LoadsChanged();
    return absl::OkStatus();
  }
  auto dr = std::find_if(im.drags.begin(), im.drags.end(),
                         [id](const Impl::DragLoad& l) { return l.id == id; });
  if (dr != im.drags.end()) {
    im.drags.erase(dr);
    im.RebuildPressure();
    im.LoadsChanged();
    return absl::OkStatus();
  }
  return absl::NotFoundError(absl::StrCat("load id ", id, " not found (active point forces: ",
                                          IdList(im.point_loads), "; pressures: ",
                                          IdList(im.pressures), "; drags: ", IdList(im.drags),
                                          ")"));
}

std::vector<int64_t> Solid::load_ids() const {
  std::vector<int64_t> ids;
  for (const auto& l : impl_->point_loads) ids.push_back(l.id);
  for (const auto& l : impl_->pressures) ids.push_back(l.id);
  for (const auto& l : impl_->drags) ids.push_back(l.id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::vector<int64_t> Solid::constraint_ids() const {
  std::vector<int64_t> ids;
  for (const auto& c : impl_->fixes) ids.push_back(c.id);
  return ids;
}

Eigen::Vector3d Solid::gravity() const { return impl_->gravity; }

std::vector<Solid::LoadInfo> Solid::ActiveLoads() const {
  const Impl& im = *impl_;
  std::vector<LoadInfo> out;
  std::vector<double> shape;
  for (const Impl::PointLoad& load : im.point_loads) {
    LoadInfo info;
    info.id = load.id;
    info.kind = LoadInfo::Kind::kPointForce;
    info.material_points.push_back(V(load.msg.position()));
    info.positions.push_back(im.PositionAt(load.at, p_, shape));  // where it acts
    info.force = V(load.msg.force());
    out.push_back(std::move(info));
  }
  for (const Impl::PressureLoad& load : im.pressures) {
    LoadInfo info;
    info.id = load.id;
    info.kind = LoadInfo::Kind::kPressure;
    info.pascals = load.msg.pascals();
    info.region = load.msg.region();
    info.quads = load.quads;
    out.push_back(std::move(info));
  }
  for (const Impl::DragLoad& load : im.drags) {
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
  for (const Impl::FixConstraint& c : impl_->fixes) out.push_back({c.id, c.region, c.points});
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
  for (int32_t i : points) {
    if (im.fix_count[i]++ == 0) {
      im.hold.row(i) = p_.row(i);
      p_prev_.row(i) = p_.row(i);
    }
  }
  const int64_t id = im.next_id++;
  im.fixes.push_back({id, r, std::move(points)});
  ApplyFixed();
  im.forces_valid = false;
  im.ledger_rebase = true;
  return id;
}

absl::Status Solid::Unfix(int64_t constraint_id) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedUnfix> prepared, PrepareUnfix(constraint_id));
  return ApplyUnfix(*prepared);
}

absl::StatusOr<std::shared_ptr<Solid::PreparedUnfix>> Solid::PrepareUnfix(
    int64_t constraint_id) const {
  const Impl& im = *impl_;
  auto it = std::find_if(im.fixes.begin(), im.fixes.end(),
                         [constraint_id](const Impl::FixConstraint& c) { return c.id == constraint_id; });
  if (it == im.fixes.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", constraint_id,
                                            " not found (active fixed regions: ",
                                            IdList(im.fixes), ")"));
  }
  auto out = std::make_shared<PreparedUnfix>();
  out->constraint_id = constraint_id;
  out->made_for = im.PreparedForNow();
  out->count = im.fix_count;
  for (int32_t i : it->points) --out->count[i];
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
  auto it = std::find_if(im.fixes.begin(), im.fixes.end(), [p](const Impl::FixConstraint& c) {
    return c.id == p->constraint_id;
  });
  im.fix_count = std::move(p->count);
  im.fixes.erase(it);
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
  im.ledger_rebase = true;
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
