#include "solver/sculpt/apply.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/common/status_macros.h"
#include "solver/scene/build.h"
#include "solver/scene/inline_mesh.h"
#include "solver/scene/scene_loader.h"
#include "solver/sculpt/edit_common.h"
#include "solver/sculpt/topology.h"

namespace dynsolid::sculpt {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The edit's error with the command's field path in front: the topology
// functions name their argument ("cells[2]: ..."), the reply names the
// request field ("edit.delete_cells.cells[2]: ...").
absl::Status Prefixed(const absl::Status& s, const char* kind) {
  return absl::Status(s.code(), absl::StrCat("edit.", kind, ".", std::string(s.message())));
}

// The cell (faces: the boundary face) whose rest centroid is nearest x.
int32_t NearestCell(const mesh::CellComplex& c, const Vec3& p) {
  const Eigen::Vector3d x(p.x(), p.y(), p.z());
  int32_t best = 0;
  double d = INFINITY;
  for (int32_t i = 0; i < c.num_cells(); ++i) {
    const double e = (c.CellCentroid(i) - x).squaredNorm();
    if (e < d) {
      d = e;
      best = i;
    }
  }
  return best;
}

int32_t NearestBoundaryFace(const mesh::CellComplex& c, const Vec3& p) {
  const Eigen::Vector3d x(p.x(), p.y(), p.z());
  int32_t best = -1;
  double d = INFINITY;
  for (int32_t f = 0; f < c.num_faces(); ++f) {
    if (!c.face_is_boundary(f)) continue;
    const double e = (c.FaceCentroid(f) - x).squaredNorm();
    if (e < d) {
      d = e;
      best = f;
    }
  }
  return best;
}

// A bake: the same cells and sharp edges over the baked positions (which
// become both the rest and the current ones). The checks of every edit
// refuse an inverted cell.
absl::StatusOr<EditResult> BakeShape(const mesh::CellComplex& rest,
                                     const std::vector<uint8_t>& sharp, const dynsolid::Bake& b) {
  const int32_t nv = rest.num_vertices();
  if (b.rest_positions_size() != 3 * nv) {
    return absl::InvalidArgumentError(absl::StrCat(
        "rest_positions: ", b.rest_positions_size(), " values for ", nv,
        " control points (3 each; the server fills them in with the solid's positions)"));
  }
  EditResult result;
  result.mesh = internal::ToInput(rest);
  double moved = 0;
  for (int32_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) result.mesh.vertices(i, k) = b.rest_positions(3 * i + k);
    moved = std::max(moved, (result.mesh.vertices.row(i) - rest.positions().row(i)).norm());
  }
  result.current = result.mesh.vertices;
  result.vertex_sources = internal::IdentitySources(nv);
  result.cell_source.resize(rest.num_cells());
  for (int32_t c = 0; c < rest.num_cells(); ++c) result.cell_source[c] = c;
  result.summary = absl::StrCat("baked the current shape into the rest shape (",
                                internal::Count(nv, "control point"), ", moved by up to ",
                                absl::StrFormat("%.3g", moved), " m)");
  return internal::Finish("bake", std::move(result), internal::SharpPairs(rest, sharp));
}

// Ids, then the items nearest the `near` points.
template <typename Ids, typename Points3, typename Nearest>
std::vector<int32_t> Select(const Ids& ids, const Points3& near, Nearest nearest) {
  std::vector<int32_t> out(ids.begin(), ids.end());
  for (const Vec3& p : near) out.push_back(nearest(p));
  return out;
}

absl::StatusOr<EditResult> Dispatch(const mesh::CellComplex& rest, const Points& current,
                                    const std::vector<uint8_t>& sharp, const TopologyEdit& e) {
  switch (e.kind_case()) {
    case TopologyEdit::kDeleteCells: {
      const std::vector<int32_t> cells =
          Select(e.delete_cells().cells(), e.delete_cells().near(),
                 [&](const Vec3& p) { return NearestCell(rest, p); });
      absl::StatusOr<EditResult> r = DeleteCells(rest, current, sharp, cells);
      if (!r.ok()) return Prefixed(r.status(), "delete_cells");
      return r;
    }
    case TopologyEdit::kExtrudeFaces: {
      const dynsolid::ExtrudeFaces& x = e.extrude_faces();
      const std::vector<int32_t> faces = Select(
          x.faces(), x.near(), [&](const Vec3& p) { return NearestBoundaryFace(rest, p); });
      absl::StatusOr<EditResult> r = sculpt::ExtrudeFaces(
          rest, current, sharp, faces, x.distance(), x.layers() == 0 ? 1 : x.layers());
      if (!r.ok()) return Prefixed(r.status(), "extrude_faces");
      return r;
    }
    case TopologyEdit::kMergeFaces: {
      const dynsolid::MergeFaces& m = e.merge_faces();
      int32_t a = m.face_a(), b = m.face_b();
      if (m.near_size() != 0) {
        if (m.near_size() != 2) {
          return absl::InvalidArgumentError(absl::StrCat(
              "edit.merge_faces.near: two points (one per face), got ", m.near_size()));
        }
        a = NearestBoundaryFace(rest, m.near(0));
        b = NearestBoundaryFace(rest, m.near(1));
      }
      absl::StatusOr<EditResult> r = sculpt::MergeFaces(rest, current, sharp, a, b);
      if (!r.ok()) return Prefixed(r.status(), "merge_faces");
      return r;
    }
    case TopologyEdit::kSubdivideCells: {
      const std::vector<int32_t> cells =
          Select(e.subdivide_cells().cells(), e.subdivide_cells().near(),
                 [&](const Vec3& p) { return NearestCell(rest, p); });
      absl::StatusOr<EditResult> r = SubdivideCells(rest, current, sharp, cells);
      if (!r.ok()) return Prefixed(r.status(), "subdivide_cells");
      return r;
    }
    case TopologyEdit::kSharpEdges: {
      std::vector<std::array<int32_t, 2>> edges;
      for (const EdgeRef& edge : e.sharp_edges().edges()) edges.push_back({edge.v0(), edge.v1()});
      absl::StatusOr<EditResult> r =
          SetSharp(rest, current, sharp, edges, e.sharp_edges().sharp());
      if (!r.ok()) return Prefixed(r.status(), "sharp_edges");
      return r;
    }
    case TopologyEdit::kBake: {
      absl::StatusOr<EditResult> r = BakeShape(rest, sharp, e.bake());
      if (!r.ok()) return Prefixed(r.status(), "bake");
      return r;
    }
    case TopologyEdit::KIND_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("edit: no edit kind is set");
}

}  // namespace

absl::StatusOr<PreparedEdit> PrepareEdit(const Scene& scene, const solid::Solid& solid,
                                         const TopologyEdit& edit) {
  const auto t0 = Clock::now();
  RETURN_IF_ERROR(scene::ValidateValues(edit, "edit"));
  const scene::Discretization& d = solid.discretization();
  // The edit at rest (rest positions stand in for the current ones here:
  // nothing decided at rest depends on them; FinishEdit places the new
  // points where the solid is then).
  const mesh::CellComplex& rest = d.control();
  const bool bake = edit.kind_case() == TopologyEdit::kBake;
  if (bake) RETURN_IF_ERROR(solid.CanBake());
  ASSIGN_OR_RETURN(EditResult r, Dispatch(rest, rest.positions(), d.control_sharp, edit));

  // The edited scene: the new control mesh inline (final positions: no
  // scale, translation or local refinement left to apply), its sharp edges
  // listed, the levels the solid was built with.
  PreparedEdit out;
  out.edit = edit;
  Scene& edited = out.scene;
  edited = scene;
  ControlMesh* m = edited.mutable_mesh();
  m->Clear();
  *m->mutable_inline_mesh() = scene::InlineFromMesh(r.mesh);
  edited.mutable_subdivision()->set_levels(d.hierarchy.levels);
  SharpFeatures* sharp = edited.mutable_sharp();
  sharp->Clear();
  for (const auto& [a, b] : r.sharp_edges) {
    EdgeRef* e = sharp->add_edges();
    e->set_v0(a);
    e->set_v1(b);
  }
  // A bake's positions: its result's (BakeShape checked their count).
  const Points& baked = r.current;
  if (bake) {
    // Traced points follow their material points to their baked rest
    // positions (the scene names them by rest position).
    for (TracedPoint& tp : *edited.mutable_traced()) {
      absl::StatusOr<Eigen::Vector3d> x =
          solid.BakedPosition(Eigen::Vector3d(tp.position().x(), tp.position().y(), tp.position().z()), baked);
      if (!x.ok()) continue;
      tp.mutable_position()->set_x(x->x());
      tp.mutable_position()->set_y(x->y());
      tp.mutable_position()->set_z(x->z());
    }
  }
  out.phases.edit = MsSince(t0);
  auto t_phase = Clock::now();
  absl::StatusOr<scene::Discretization> nd =
      r.complex != nullptr ? scene::Discretize(edited, std::move(*r.complex), std::nullopt)
                           : scene::Discretize(edited, r.mesh, std::nullopt);
  if (!nd.ok()) return absl::Status(nd.status().code(), absl::StrCat("edit: ", nd.status().message()));
  out.cells_before = rest.num_cells();
  out.vertices_before = rest.num_vertices();
  out.cells_after = nd->control().num_cells();
  out.vertices_after = nd->control().num_vertices();
  out.elements_after =
      nd->elements.num_cubic() + nd->elements.num_linear() + nd->elements.num_pyramid();
  out.phases.discretize = MsSince(t_phase);
  t_phase = Clock::now();
  absl::StatusOr<std::unique_ptr<solid::Solid>> built =
      solid.BuildRemeshed(edited, *std::move(nd), r.cell_source, bake ? &baked : nullptr);
  if (!built.ok()) {
    return absl::Status(built.status().code(), absl::StrCat("edit: ", built.status().message()));
  }
  out.phases.build = MsSince(t_phase);
  out.built = *std::move(built);
  out.rest_mesh = std::move(r.mesh);
  out.milliseconds = MsSince(t0);
  return out;
}

absl::StatusOr<AppliedEdit> FinishEdit(PreparedEdit prepared, const solid::Solid& solid) {
  const auto t0 = Clock::now();
  const scene::Discretization& d = solid.discretization();
  // The same edit again, now with the current positions (cheap: the control
  // mesh only). Its rest mesh is the prepared one's.
  ASSIGN_OR_RETURN(EditResult r, Dispatch(d.control(), solid.control_positions(),
                                          d.control_sharp, prepared.edit));
  if (r.mesh.vertices != prepared.rest_mesh.vertices || r.mesh.cells != prepared.rest_mesh.cells) {
    return absl::InternalError(
        "edit: the solid's control mesh changed between preparing and finishing the edit");
  }
  AppliedEdit out;
  out.cells_before = prepared.cells_before;
  out.cells_after = prepared.cells_after;
  out.vertices_before = prepared.vertices_before;
  out.vertices_after = prepared.vertices_after;
  out.elements_after = prepared.elements_after;
  const bool bake = prepared.edit.kind_case() == TopologyEdit::kBake;
  solid::Solid::TopologyTransfer t{r.current, r.vertex_sources, r.cell_source};
  if (bake) {
    RETURN_IF_ERROR(solid.CanBake());
    t.baked = &r.current;
  }
  absl::StatusOr<std::unique_ptr<solid::Solid>> s =
      solid.CarryOver(std::move(prepared.built), prepared.scene, t, &out.transfer);
  if (!s.ok()) return absl::Status(s.status().code(), absl::StrCat("edit: ", s.status().message()));
  out.solid = *std::move(s);
  if (bake) out.solid->SetAtRest(r.current);  // at rest in its baked shape
  out.scene = out.transfer.scene;
  out.summary = r.summary;
  out.prepare_milliseconds = prepared.milliseconds;
  out.prepare_phases = prepared.phases;
  out.milliseconds = MsSince(t0);
  return out;
}

absl::StatusOr<AppliedEdit> ApplyEdit(const Scene& scene, const solid::Solid& solid,
                                      const TopologyEdit& edit) {
  const auto t0 = Clock::now();
  ASSIGN_OR_RETURN(PreparedEdit prepared, PrepareEdit(scene, solid, edit));
  ASSIGN_OR_RETURN(AppliedEdit out, FinishEdit(std::move(prepared), solid));
  out.milliseconds = MsSince(t0);
  return out;
}

absl::StatusOr<EditResult> EditAtRest(const scene::Discretization& d, const TopologyEdit& edit) {
  RETURN_IF_ERROR(scene::ValidateValues(edit, "edit"));
  const mesh::CellComplex& rest = d.control();
  return Dispatch(rest, rest.positions(), d.control_sharp, edit);
}

absl::StatusOr<std::unique_ptr<solid::Solid>> BuildEdited(const Scene& scene, int threads) {
  ASSIGN_OR_RETURN(scene::Discretization d, scene::BuildDiscretization(scene, "", std::nullopt));
  return solid::Solid::Create(scene, std::move(d), threads);
}

}  // namespace dynsolid::sculpt
