// Carrying a solid's state over a topology edit (solid.h Remeshed): the
// edit itself is a pure function of the control mesh (solver/sculpt/); this
// builds the solid of the new mesh and moves positions, velocities,
// materials, loads, drags, constraints and the clock onto it.
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/material_transfer.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

// A region's control cells mapped to the new mesh: every new cell whose
// source is one of them.
// A region's control cells and control points renumbered for the new mesh:
// cells through cell_source, points through `point_map` (old point -> new,
// -1: gone; null: unknown here, the points are left out).
Region RemapRegion(const Region& r, const std::vector<int32_t>& cell_source,
                   const std::vector<int32_t>* point_map = nullptr) {
  if (r.control_cells_size() == 0 && r.control_points_size() == 0) return r;
  Region out = r;
  out.clear_control_points();
  for (int32_t old : r.control_points()) {
    if (point_map != nullptr && old < static_cast<int32_t>(point_map->size()) &&
        (*point_map)[old] >= 0) {
      out.add_control_points((*point_map)[old]);
    }
  }
  out.clear_control_cells();
  for (size_t c = 0; c < cell_source.size(); ++c) {
    for (int32_t old : r.control_cells()) {
      if (cell_source[c] == old) {
        out.add_control_cells(static_cast<int32_t>(c));
        break;
      }
    }
  }
  return out;
}

// The scene a remeshed solid is created from: its own items only (the
// runtime ones are carried over with their ids); penalty springs' control
// cells renumbered.
Scene CleanScene(const Scene& scene, const std::vector<int32_t>& cell_source) {
  Scene clean = scene;
  clean.mutable_loads()->clear_point_forces();
  clean.mutable_loads()->clear_pressures();
  clean.mutable_loads()->clear_gravity();
  clean.mutable_constraints()->clear_fixed();
  clean.clear_traced();
  clean.mutable_materials()->clear_regions();
  clean.clear_design();  // the materials are carried over
  for (PenaltySpring& s : *clean.mutable_constraints()->mutable_springs()) {
    *s.mutable_region() = RemapRegion(s.region(), cell_source);
  }
  return clean;
}

}  // namespace

absl::Status Solid::CanBake() const {
  for (const LoadSet::PressureLoad& l : impl_->loads.pressures()) {
    if (l.msg.region().shape_case() != Region::SHAPE_NOT_SET) {
      return absl::FailedPreconditionError(absl::StrCat(
          "bake: pressure ", l.id,
          " selects its faces by a box or sphere at rest, which a bake would move; remove it "
          "(or give its region by control cells) and bake again"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<Eigen::Vector3d> Solid::BakedPosition(const Eigen::Vector3d& x,
                                                     const Points& baked) const {
  ASSIGN_OR_RETURN(const Impl::ControlWeights row, impl_->ControlRow(x));
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  for (const auto& [i, w] : row) out += w * baked.row(i).transpose();
  return out;
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::Remeshed(const Scene& scene,
                                                       scene::Discretization discretization,
                                                       const TopologyTransfer& t,
                                                       TransferReport* report) const {
  ASSIGN_OR_RETURN(std::unique_ptr<Solid> built,
                   BuildRemeshed(scene, std::move(discretization), t.cell_source, t.baked));
  return CarryOver(std::move(built), scene, t, report);
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::BuildRemeshed(
    const Scene& scene, scene::Discretization discretization,
    const std::vector<int32_t>& cell_source, const Points* baked) const {
  const Impl& old = *impl_;
  // A bake keeps every element but moves its rest nodes to A P: the old
  // elements are found by those (the new solid's rest nodes, bit for bit).
  const Points baked_nodes = baked != nullptr ? old.node_rows.Multiply(*baked) : Points();
  const Points& old_nodes = baked != nullptr ? baked_nodes : old.rest_nodes;
  const mesh::CellComplex& control = discretization.control();
  const int32_t old_cells = d_.control().num_cells();
  if (static_cast<int32_t>(cell_source.size()) != control.num_cells()) {
    return absl::InternalError(absl::StrCat("topology transfer: ", cell_source.size(),
                                            " cell sources for ", control.num_cells(), " cells"));
  }
  for (int32_t c : cell_source) {
    if (c >= old_cells) return absl::InternalError(absl::StrCat("topology transfer: cell source ", c));
  }

  // Materials: uniform (one array of base samples) needs no transfer.
  const models::MaterialPoint base = ToPoint(scene.materials().base());
  const models::ElementLayout& layout = *old.layout;
  bool uniform = layout.materials.size() == 1;
  for (size_t k = 0; uniform && k < layout.materials[0].size(); ++k) {
    uniform = layout.materials[0][k] == base;
  }
  // Painted: the old samples carried onto the new cells
  // (material_transfer.h).
  std::unique_ptr<MaterialTransfer> transfer;
  models::MaterialSampler sampler;
  models::ElementMaterials whole;
  if (!uniform) {
    transfer = std::make_unique<MaterialTransfer>(layout, old_nodes, old.rest_nodes,
                                                  d_.hierarchy.control_cell, old_cells,
                                                  cell_source, base);
    sampler = [&transfer](const Eigen::Vector3d& x, int32_t cell) {
      return transfer->Sample(x, cell);
    };
    whole = [&transfer](int kind, const fem::NodeMatrixX3& x, int32_t cell) {
      return transfer->Whole(kind, x, cell);
    };
  }
  ASSIGN_OR_RETURN(std::unique_ptr<Solid> out,
                   CreateWith(CleanScene(scene, cell_source), std::move(discretization),
                              old.pool->size(), uniform ? nullptr : &sampler, this,
                              uniform ? nullptr : &whole));
  // The explicit integrator set up here, off the loop, for the fixed set
  // the carried pins will give (pins do not change while an edit builds:
  // the server lets only loads and drags pass it); CarryOver's own set-up
  // then finds it made for those very values and keeps it (SetSubsteps).
  Impl& im = *out->impl_;
  if (!im.use_implicit) {
    const std::vector<uint8_t> scene_fixed = im.fixed;
    for (const LoadSet::FixConstraint& c : old.loads.fixes()) {
      if (baked != nullptr) {
        for (int32_t i : c.points) im.fixed[i] = 1;  // a bake keeps the points
        continue;
      }
      for (int32_t i : im.SelectControlPoints(RemapRegion(c.region, cell_source))) im.fixed[i] = 1;
    }
    im.SetSubsteps(im.substeps, out->h_);
    im.fixed = scene_fixed;
  }
  return out;
}

namespace {

// The old solid's loads, drags and constraints (with their ids) located on
// the new one, `im`, whose rest positions are the old ones moved by
// `moved` (a bake moves them; else the identity); what no longer finds its
// place is listed in the report's dropped loads and constraints.
LoadSet::Contents CarryLoads(const Solid::Impl& old, const Solid::Impl& im,
                             const Solid::TopologyTransfer& t,
                             const std::vector<int32_t>& point_map,
                             const std::function<Vec3(const Vec3&)>& moved,
                             Solid::TransferReport& rep) {
  LoadSet::Contents loads;
  loads.next_id = old.loads.next_id();
  loads.gravity = old.loads.gravity();
  const bool snap = im.settings.snap_forces_to_quadrature();
  for (const LoadSet::PointLoad& l : old.loads.point_loads()) {
    PointForce msg = l.msg;
    *msg.mutable_position() = moved(msg.position());
    absl::StatusOr<MaterialLocation> at = im.Locate(V(msg.position()), snap);
    if (at.ok()) {
      loads.point_loads.push_back({l.id, std::move(msg), *at});
    } else {
      rep.dropped_loads.push_back(l.id);
    }
  }
  for (const LoadSet::PressureLoad& l : old.loads.pressures()) {
    Pressure msg = l.msg;
    *msg.mutable_region() = RemapRegion(msg.region(), t.cell_source, nullptr);
    std::vector<int32_t> quads = im.SelectQuads(msg.region());
    if (quads.empty()) {
      rep.dropped_loads.push_back(l.id);
    } else {
      loads.pressures.push_back({l.id, std::move(msg), std::move(quads)});
    }
  }
  for (const LoadSet::DragLoad& l : old.loads.drags()) {
    Drag drag = l.drag;
    CurveDrag shape = l.shape;
    *drag.mutable_material_point() = moved(drag.material_point());
    for (Vec3& x : *shape.mutable_material_points()) x = moved(x);
    absl::StatusOr<LoadSet::DragLoad> carried = l.curve ? im.MakeCurve(shape) : im.MakeDrag(drag);
    if (carried.ok()) {
      carried->id = l.id;
      loads.drags.push_back(*std::move(carried));
    } else {
      rep.dropped_loads.push_back(l.id);
    }
  }
  std::sort(rep.dropped_loads.begin(), rep.dropped_loads.end());
  for (const LoadSet::FixConstraint& c : old.loads.fixes()) {
    Region region;
    if (t.baked != nullptr) {
      // The same control points, whatever their new rest positions.
      for (int32_t i : c.points) region.add_control_points(i);
    } else {
      region = RemapRegion(c.region, t.cell_source, &point_map);
    }
    std::vector<int32_t> points = im.SelectControlPoints(region);
    if (points.empty()) {
      rep.dropped_constraints.push_back(c.id);
      continue;
    }
    loads.fixes.push_back({c.id, std::move(region), std::move(points)});
  }
  return loads;
}

}  // namespace

absl::StatusOr<std::unique_ptr<Solid>> Solid::CarryOver(std::unique_ptr<Solid> out,
                                                        const Scene& scene,
                                                        const TopologyTransfer& t,
                                                        TransferReport* report) const {
  const Impl& old = *impl_;
  const mesh::CellComplex& control = out->discretization().control();
  const int32_t nv = control.num_vertices();
  if (t.current.rows() != nv || static_cast<int32_t>(t.vertex_sources.size()) != nv ||
      static_cast<int32_t>(t.cell_source.size()) != control.num_cells()) {
    return absl::InternalError(absl::StrCat(
        "topology transfer: ", t.current.rows(), " positions and ", t.vertex_sources.size(),
        " vertex sources for ", nv, " control points, ", t.cell_source.size(),
        " cell sources for ", control.num_cells(), " cells"));
  }
  const int32_t old_nc = static_cast<int32_t>(p_.rows());
  for (int32_t v = 0; v < nv; ++v) {
    if (t.vertex_sources[v].empty()) {
      return absl::InternalError(absl::StrCat("topology transfer: vertex ", v, " has no source"));
    }
    for (const auto& [src, w] : t.vertex_sources[v]) {
      if (src < 0 || src >= old_nc || !std::isfinite(w)) {
        return absl::InternalError(absl::StrCat("topology transfer: vertex ", v, " source ", src));
      }
    }
  }
  Scene clean = CleanScene(scene, t.cell_source);
  Solid& s = *out;
  Impl& im = *s.impl_;
  TransferReport local;
  TransferReport& rep = report != nullptr ? *report : local;
  rep = TransferReport();

  // Old control point -> new, for regions given by control points, and
  // back: a survivor is the first point whose only source it is, with
  // weight 1 (later ones, such as an extrusion's copies, are new points).
  std::vector<int32_t> point_map(old_nc, -1), point_source(nv, -1);
  for (int32_t v = 0; v < nv; ++v) {
    const auto& src = t.vertex_sources[v];
    if (src.size() == 1 && src[0].second == 1.0 && point_map[src[0].first] < 0) {
      point_map[src[0].first] = v;
      point_source[v] = src[0].first;
    }
  }

  // Clay: each cell keeps the flow law of the cell it comes from (new
  // cells the scene's), and the units the edit left alone keep their
  // plastic offsets (CarryPlasticity); a bake resets them (its rest shape
  // is the baked one).
  if (old.plasticity != nullptr && (im.cell_model != nullptr || im.corotational != nullptr)) {
    std::vector<material::FlowLaw> laws =
        im.plasticity != nullptr ? im.plasticity->laws()
                                 : std::vector<material::FlowLaw>(control.num_cells());
    const std::vector<material::FlowLaw>& was = old.plasticity->laws();
    for (int32_t c = 0; c < control.num_cells(); ++c) {
      const int32_t src = t.cell_source[c];
      if (src >= 0 && src < static_cast<int32_t>(was.size())) laws[c] = was[src];
    }
    if (im.plasticity == nullptr) {
      im.plasticity = std::make_unique<material::Plasticity>(std::move(laws));
      im.AttachPlasticity();
    } else {
      im.plasticity->set_laws(std::move(laws));
    }
    if (t.baked == nullptr) im.CarryPlasticity(old, point_source, t.cell_source);
  }

  // Loads, drags and constraints, with their ids.
  // A bake moves rest positions: a material point's new one is its control
  // row times the baked positions.
  auto moved = [&](const Vec3& x) -> Vec3 {
    if (t.baked == nullptr) return x;
    absl::StatusOr<Eigen::Vector3d> b = BakedPosition(V(x), *t.baked);
    if (!b.ok()) return x;
    Vec3 out;
    out.set_x(b->x());
    out.set_y(b->y());
    out.set_z(b->z());
    return out;
  };
  LoadSet::Contents loads = CarryLoads(old, im, t, point_map, moved, rep);
  // A survivor held before is held where it was. (A new point whose only
  // source is a held point, such as an extruded copy of a pinned face's
  // vertex, is not that point: it is held where it is, if a pin takes it.)
  std::vector<uint8_t> was_fixed(nv, 0);
  for (int32_t v = 0; v < nv; ++v) {
    was_fixed[v] = point_source[v] >= 0 && old.fixed[point_source[v]] != 0;
  }
  for (int i = 0; i < scene.traced_size(); ++i) {
    absl::StatusOr<MaterialLocation> at =
        im.Locate(V(scene.traced(i).position()), false);
    if (at.ok()) {
      im.traced.push_back(*at);
      s.traced_names_.push_back(scene.traced(i).name());
      *clean.add_traced() = scene.traced(i);
    } else {
      rep.dropped_traced.push_back(scene.traced(i).name());
    }
  }

  // Positions and velocities.
  Points held = t.current;
  for (int32_t v = 0; v < nv; ++v) {
    if (was_fixed[v]) held.row(v) = old.loads.held_at().row(point_source[v]);
  }
  im.loads = LoadSet(std::move(loads), std::move(held));
  s.p_ = t.current;
  for (int32_t v = 0; v < nv; ++v) {
    if (im.loads.held(v)) s.p_.row(v) = im.loads.held_at().row(v);
  }
  im.fixed = im.loads.FixedFlags();
  im.SetSubsteps(im.substeps, s.h_);
  s.p_prev_ = s.p_;
  for (int32_t v = 0; v < nv; ++v) {
    if (im.fixed[v]) continue;
    Eigen::RowVector3d vel = Eigen::RowVector3d::Zero();
    for (const auto& [src, w] : t.vertex_sources[v]) {
      vel += w * (p_.row(src) - p_prev_.row(src)) / old.h_sub;
    }
    s.p_prev_.row(v) = s.p_.row(v) - im.h_sub * vel;
  }
  im.RebuildConstantLoads();
  im.RebuildPressure();
  im.forces_valid = false;
  im.ledger.RequestRebase();
  s.time_ = time_;
  s.steps_ = steps_;
  s.rollbacks_ = rollbacks_;
  s.topology_version_ = topology_version_ + 1;
  s.report_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  s.report_.gravity = im.loads.has_gravity();
  s.report_.fixed_control_points =
      static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  // (The geometry it covers was hashed by the build: only the scene here.)
  im.fingerprint = s.Fingerprint(clean);
  rep.scene = std::move(clean);
  return out;
}

}  // namespace dynsolid::solid
