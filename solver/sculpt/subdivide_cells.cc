// SubdivideCells: local MacCracken-Joy refinement of chosen cells (docs/model.md 8).
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/sculpt/edit_common.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::sculpt {

absl::StatusOr<EditResult> SubdivideCells(const mesh::CellComplex& rest, const Points& current,
                                          const std::vector<uint8_t>& sharp,
                                          std::span<const int32_t> cells) {
  RETURN_IF_ERROR(internal::CheckState(rest, current, sharp));
  RETURN_IF_ERROR(internal::CheckIds(cells, rest.num_cells(), "cells", "cell"));
  subdivision::SubdivisionOptions options;
  options.sharp_edges = sharp;
  options.cells.assign(cells.begin(), cells.end());
  options.validate_geometry = true;
  absl::StatusOr<subdivision::Level> level = subdivision::SubdivideOnce(rest, options);
  if (!level.ok()) {
    return absl::Status(level.status().code(),
                        absl::StrCat("subdivide: ", level.status().message()));
  }
  const mesh::CellComplex& fine = level->fine;
  EditResult result;
  result.mesh = internal::ToInput(fine);
  result.current = level->a * current;
  const int32_t nv = fine.num_vertices();
  result.vertex_sources.resize(nv);
  for (int32_t r = 0; r < nv; ++r) {
    for (subdivision::SparseMatrix::InnerIterator it(level->a, r); it; ++it) {
      result.vertex_sources[r].push_back({static_cast<int32_t>(it.col()), it.value()});
    }
  }
  result.cell_source = level->parent_cell;
  result.summary = absl::StrCat("subdivided ", internal::Count(cells.size(), "cell"), ": ",
                                rest.num_cells(), " -> ", internal::Count(fine.num_cells(), "cell"),
                                ", ", rest.num_vertices(), " -> ", internal::Count(nv, "vertex"));
  std::vector<uint8_t> tags = level->sharp_edges;
  tags.resize(fine.num_edges(), 0);
  return internal::Finish("subdivide", std::move(result), internal::SharpPairs(fine, tags));
}

}  // namespace dynsolid::sculpt
