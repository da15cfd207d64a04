#include "solver/sculpt/revert.h"

#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/scene/inline_mesh.h"
#include "solver/sculpt/design_scene.h"
#include "solver/sculpt/edit_common.h"

namespace dynsolid::sculpt {
namespace {

// `before` in the form an edit leaves a scene in (apply.h): the control
// mesh of `d` inline at its rest positions (no file, generator, scale or
// local refinement left to apply), its sharp edges listed, its levels. A
// session rebuilds a solid from a scene with BuildEdited (a revert's undo,
// crash recovery), which must give the same discretization as the one
// built here, or a saved state will not restore into it.
absl::StatusOr<std::pair<Scene, scene::Discretization>> SelfContained(
    const Scene& before, const scene::Discretization& d) {
  std::pair<Scene, scene::Discretization> out;
  out.first = SelfContainedScene(before, d);
  out.first.clear_design();  // the materials are carried over
  const mesh::MeshInput input = internal::ToInput(d.control());
  ASSIGN_OR_RETURN(out.second, scene::Discretize(out.first, input, std::nullopt));
  return out;
}

}  // namespace

absl::StatusOr<AppliedEdit> RevertEdit(const Scene& before, scene::Discretization d_before,
                                       const solid::Solid& solid, const TopologyEdit& edit) {
  const auto t0 = std::chrono::steady_clock::now();
  // The edit again at rest on the mesh before it: where each vertex and
  // cell of the current mesh came from.
  ASSIGN_OR_RETURN(EditResult r, EditAtRest(d_before, edit));
  const mesh::CellComplex& now = solid.discretization().control();
  const mesh::CellComplex& was = d_before.control();
  if (static_cast<int32_t>(r.vertex_sources.size()) != now.num_vertices() ||
      static_cast<int32_t>(r.cell_source.size()) != now.num_cells()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the control mesh is no longer the one this edit made (", now.num_cells(), " cells and ",
        now.num_vertices(), " vertices now, the edit made ", r.cell_source.size(), " and ",
        r.vertex_sources.size(), ")"));
  }
  const int32_t nb = was.num_vertices();
  const int32_t nc = now.num_vertices();
  // Kept vertices: a current vertex that is exactly one old vertex.
  std::vector<int32_t> kept(nb, -1);
  for (int32_t w = 0; w < nc; ++w) {
    const auto& s = r.vertex_sources[w];
    if (s.size() == 1 && s[0].second == 1.0 && s[0].first >= 0 && s[0].first < nb &&
        kept[s[0].first] < 0) {
      kept[s[0].first] = w;
    }
  }
  const Points& p = solid.control_positions();
  const Points& rest_now = now.positions();
  const Points& rest_was = was.positions();
  solid::Solid::TopologyTransfer t;
  t.current.resize(nb, 3);
  t.vertex_sources.resize(nb);
  for (int32_t v = 0; v < nb; ++v) {
    int32_t w = kept[v];
    if (w >= 0) {
      t.current.row(v) = p.row(w);
      t.vertex_sources[v] = {{w, 1.0}};
      continue;
    }
    // Removed: back at rest, moved as the nearest current vertex moved.
    double best = INFINITY;
    for (int32_t k = 0; k < nc; ++k) {
      const double d = (rest_now.row(k) - rest_was.row(v)).squaredNorm();
      if (d < best) {
        best = d;
        w = k;
      }
    }
    if (w < 0) return absl::InvalidArgumentError("the edited control mesh has no vertex");
    t.current.row(v) = rest_was.row(v) + (p.row(w) - rest_now.row(w));
    t.vertex_sources[v] = {{w, 1.0}};
  }
  // Cells: each old cell from the first current cell that is (or came
  // from) it; -1 (base material) for a cell the edit removed.
  t.cell_source.assign(was.num_cells(), -1);
  for (int32_t k = static_cast<int32_t>(r.cell_source.size()) - 1; k >= 0; --k) {
    const int32_t c = r.cell_source[k];
    if (c >= 0 && c < was.num_cells()) t.cell_source[c] = k;
  }
  AppliedEdit out;
  out.cells_before = now.num_cells();
  out.vertices_before = nc;
  out.cells_after = was.num_cells();
  out.vertices_after = nb;
  out.elements_after = d_before.elements.num_cubic() + d_before.elements.num_linear() +
                       d_before.elements.num_pyramid();
  ASSIGN_OR_RETURN(auto own, SelfContained(before, d_before));
  ASSIGN_OR_RETURN(std::unique_ptr<solid::Solid> built,
                   solid.BuildRemeshed(own.first, std::move(own.second), t.cell_source, nullptr));
  ASSIGN_OR_RETURN(out.solid, solid.CarryOver(std::move(built), own.first, t, &out.transfer));
  out.scene = out.transfer.scene;
  out.summary = absl::StrCat("put back the control mesh from before \"", r.summary, "\" (",
                             out.cells_after, " cells, ", out.vertices_after, " vertices)");
  out.milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  out.prepare_milliseconds = out.milliseconds;
  return out;
}

}  // namespace dynsolid::sculpt
