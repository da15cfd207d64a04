// DeleteCells: drop cells, drop vertices no survivor uses (docs/model.md section 8).
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/sculpt/edit_common.h"

namespace dynsolid::sculpt {

absl::StatusOr<EditResult> DeleteCells(const mesh::CellComplex& rest, const Points& current,
                                       const std::vector<uint8_t>& sharp,
                                       std::span<const int32_t> cells) {
  RETURN_IF_ERROR(internal::CheckState(rest, current, sharp));
  const int32_t nc = rest.num_cells();
  RETURN_IF_ERROR(internal::CheckIds(cells, nc, "cells", "cell"));
  if (static_cast<int32_t>(cells.size()) == nc) {
    return absl::InvalidArgumentError(
        absl::StrCat("cells: deleting all ", nc, " cells would leave nothing; keep at least one"));
  }
  std::vector<uint8_t> gone(nc, 0);
  for (int32_t c : cells) gone[c] = 1;

  // Survivors' vertices, renumbered in old order.
  const int32_t nv = rest.num_vertices();
  std::vector<int32_t> remap(nv, -1);
  for (int32_t c = 0; c < nc; ++c) {
    if (gone[c]) continue;
    for (int32_t v : rest.cell_vertices(c)) remap[v] = 0;
  }
  int32_t kept = 0;
  for (int32_t v = 0; v < nv; ++v) {
    if (remap[v] >= 0) remap[v] = kept++;
  }

  EditResult result;
  result.mesh.vertices.resize(kept, 3);
  result.current.resize(kept, 3);
  result.vertex_sources.resize(kept);
  for (int32_t v = 0; v < nv; ++v) {
    const int32_t w = remap[v];
    if (w < 0) continue;
    result.mesh.vertices.row(w) = rest.positions().row(v);
    result.current.row(w) = current.row(v);
    result.vertex_sources[w] = {{v, 1.0}};
  }
  std::vector<int32_t> loop;
  for (int32_t c = 0; c < nc; ++c) {
    if (gone[c]) continue;
    auto& faces = result.mesh.cells.emplace_back();
    const int32_t nf = static_cast<int32_t>(rest.cell_faces(c).size());
    for (int32_t k = 0; k < nf; ++k) {
      rest.CellFaceLoop(c, k, loop);
      for (int32_t& v : loop) v = remap[v];
      faces.push_back(loop);
    }
    result.cell_source.push_back(c);
  }
  std::vector<std::array<int32_t, 2>> pairs;
  for (const auto& [a, b] : internal::SharpPairs(rest, sharp)) {
    if (remap[a] >= 0 && remap[b] >= 0) pairs.push_back({remap[a], remap[b]});
  }
  result.summary =
      absl::StrCat("deleted ", internal::Count(cells.size(), "cell"), ": -",
                   internal::Count(nv - kept, "vertex"), ", ",
                   internal::Count(nc - static_cast<int64_t>(cells.size()), "cell"), " left");
  return internal::Finish("delete", std::move(result), pairs);
}

}  // namespace dynsolid::sculpt
