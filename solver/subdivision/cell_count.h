// How many cells MacCracken-Joy subdivision makes, counted without building
// a mesh: what a server checks against its memory budget before it
// subdivides anything.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "solver/mesh/cell_complex.h"

namespace dynsolid::subdivision {

// Each vertex's valence within one level-0 cell (faces as vertex loops):
// the number of the cell's edges that meet there.
std::vector<int64_t> CellVertexValences(const std::vector<std::vector<int32_t>>& faces);

// Level-`levels` descendants (levels >= 1) of the level-1 child that
// MacCracken-Joy makes at a cell vertex of valence k. That child has 2k + 2
// vertices: two of valence k (the old vertex and the cell point) and 2k of
// valence 3, so it splits into 2 children of its own kind and 2k
// hexahedra, and a hexahedron into 8 hexahedra.
int64_t DescendantsOfVertexChild(int64_t k, int levels);

// The number of level-`levels` cells made from `control` after locally
// refining `refine_cells` (ids out of range are ignored): a cell splits
// into one child per vertex, the child at a vertex of valence k splits as
// DescendantsOfVertexChild says, and a hexahedron into 8. Exact without
// local refinement; with it, ignores the extra vertices refinement adds to
// the refined cells' neighbours (an estimate for a limit check, not a
// count).
int64_t EstimateFineCells(const mesh::MeshInput& control, std::span<const int32_t> refine_cells,
                          int levels);

}  // namespace dynsolid::subdivision
