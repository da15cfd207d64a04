// ExtrudeFaces: grow prisms out of boundary faces (docs/model.md section 8).
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/sculpt/edit_common.h"

namespace dynsolid::sculpt {
namespace {

// Per moved vertex (index into `moved`), the unit direction: the normalized
// sum of the unit normals, in `positions`, of the selected faces at it.
// Fails naming the vertex when the normals cancel (or a face is degenerate).
absl::StatusOr<std::vector<Eigen::Vector3d>> Directions(
    const mesh::CellComplex& rest, const Points& positions, std::span<const int32_t> faces,
    const std::vector<int32_t>& slot, const std::vector<int32_t>& moved, absl::string_view config) {
  const int32_t num_moved = static_cast<int32_t>(moved.size());
  std::vector<Eigen::Vector3d> dir(num_moved, Eigen::Vector3d::Zero());
  for (size_t i = 0; i < faces.size(); ++i) {
    const auto loop = rest.face_vertices(faces[i]);
    const Eigen::Vector3d n = internal::LoopNormal(positions, loop);
    if (n.isZero()) {
      return absl::InvalidArgumentError(absl::StrCat("faces[", i, "]: face ", faces[i],
                                                     " has no normal in the ", config,
                                                     " configuration (degenerate)"));
    }
    for (int32_t v : loop) dir[slot[v]] += n;
  }
  for (int32_t m = 0; m < num_moved; ++m) {
    const double len = dir[m].norm();
    if (!(len > 1e-9)) {
      return absl::InvalidArgumentError(
          absl::StrCat("faces: the selected faces' normals cancel at their shared vertex ",
                       moved[m], " in the ", config, " configuration; extrude them separately"));
    }
    dir[m] /= len;
  }
  return dir;
}

}  // namespace

absl::StatusOr<EditResult> ExtrudeFaces(const mesh::CellComplex& rest, const Points& current,
                                        const std::vector<uint8_t>& sharp,
                                        std::span<const int32_t> faces, double distance,
                                        int layers) {
  RETURN_IF_ERROR(internal::CheckState(rest, current, sharp));
  RETURN_IF_ERROR(internal::CheckIds(faces, rest.num_faces(), "faces", "face"));
  for (size_t i = 0; i < faces.size(); ++i) {
    if (!rest.face_is_boundary(faces[i])) {
      const auto& fc = rest.face_cells(faces[i]);
      return absl::InvalidArgumentError(
          absl::StrCat("faces[", i, "]: face ", faces[i], " is interior (shared by cells ", fc[0],
                       " and ", fc[1], "); only boundary faces can be extruded"));
    }
  }
  if (!std::isfinite(distance) || !(distance > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("distance: ", distance, " m; must be positive and finite"));
  }
  if (layers < 1 || layers > kMaxExtrudeLayers) {
    return absl::InvalidArgumentError(
        absl::StrCat("layers: ", layers, "; must be in [1, ", kMaxExtrudeLayers, "]"));
  }

  // The moved vertices in increasing old id (deterministic numbering).
  const int32_t nv = rest.num_vertices();
  std::vector<int32_t> slot(nv, -1);
  for (int32_t f : faces)
    for (int32_t v : rest.face_vertices(f)) slot[v] = 0;
  std::vector<int32_t> moved;
  for (int32_t v = 0; v < nv; ++v) {
    if (slot[v] >= 0) {
      slot[v] = static_cast<int32_t>(moved.size());
      moved.push_back(v);
    }
  }
  const int32_t nm = static_cast<int32_t>(moved.size());
  ASSIGN_OR_RETURN(const std::vector<Eigen::Vector3d> rest_dir,
                   Directions(rest, rest.positions(), faces, slot, moved, "rest"));
  ASSIGN_OR_RETURN(const std::vector<Eigen::Vector3d> cur_dir,
                   Directions(rest, current, faces, slot, moved, "current"));

  // Vertex of moved vertex m at layer l (layer 0: the old vertex).
  auto layer_vertex = [&](int32_t v, int l) { return l == 0 ? v : nv + (l - 1) * nm + slot[v]; };
  const int32_t total = nv + layers * nm;
  EditResult result;
  result.mesh = internal::ToInput(rest);
  result.mesh.vertices.conservativeResize(total, 3);
  result.current.resize(total, 3);
  result.current.topRows(nv) = current;
  result.vertex_sources = internal::IdentitySources(nv);
  result.vertex_sources.resize(total);
  for (int l = 1; l <= layers; ++l) {
    const double h = distance * l / layers;
    for (int32_t m = 0; m < nm; ++m) {
      const int32_t v = moved[m], w = layer_vertex(v, l);
      result.mesh.vertices.row(w) = rest.positions().row(v) + h * rest_dir[m].transpose();
      result.current.row(w) = current.row(v) + h * cur_dir[m].transpose();
      result.vertex_sources[w] = {{v, 1.0}};
    }
  }
  result.cell_source.resize(rest.num_cells());
  for (int32_t c = 0; c < rest.num_cells(); ++c) result.cell_source[c] = c;

  // Face loop (outward from the old cell, so along the extrusion): the new
  // cell's bottom is the loop reversed, its top the loop one layer up, and
  // the side over edge (a, b) is (a, b, b', a'), outward for a loop that
  // turns counter-clockwise about the extrusion direction.
  for (int l = 1; l <= layers; ++l) {
    for (int32_t f : faces) {
      const auto loop = rest.face_vertices(f);
      const size_t k = loop.size();
      auto& cell = result.mesh.cells.emplace_back();
      std::vector<int32_t> bottom, top;
      for (size_t i = 0; i < k; ++i) {
        bottom.push_back(layer_vertex(loop[(k - i) % k], l - 1));
        top.push_back(layer_vertex(loop[i], l));
      }
      cell.push_back(std::move(bottom));
      cell.push_back(std::move(top));
      for (size_t i = 0; i < k; ++i) {
        const int32_t a = loop[i], b = loop[(i + 1) % k];
        cell.push_back({layer_vertex(a, l - 1), layer_vertex(b, l - 1), layer_vertex(b, l),
                        layer_vertex(a, l)});
      }
      result.cell_source.push_back(-1);
    }
  }
  const int64_t new_cells = static_cast<int64_t>(faces.size()) * layers;
  result.summary =
      absl::StrCat("extruded ", internal::Count(faces.size(), "face"), " by ", distance, " m in ",
                   internal::Count(layers, "layer"), ": +", internal::Count(new_cells, "cell"),
                   ", +", internal::Count(static_cast<int64_t>(layers) * nm, "vertex"));
  return internal::Finish("extrude", std::move(result), internal::SharpPairs(rest, sharp));
}

}  // namespace dynsolid::sculpt
