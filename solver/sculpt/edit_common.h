// Helpers shared by the topology edits (internal to dynsolid_sculpt).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "solver/mesh/cell_complex.h"
#include "solver/sculpt/topology.h"

namespace dynsolid::sculpt::internal {

// Checks `current` (#V by 3, finite) and `sharp` (empty or one per edge).
absl::Status CheckState(const mesh::CellComplex& rest, const Points& current,
                        const std::vector<uint8_t>& sharp);

// Checks a list of ids: in [0, count), no repeats, not empty. `field` names
// the argument ("cells"), `item` the kind ("cell"): "cells[2]: cell 99 is out
// of range [0, 27)".
absl::Status CheckIds(std::span<const int32_t> ids, int32_t count, absl::string_view field,
                      absl::string_view item);

// The complex as a MeshInput: each cell's faces as loops outward from it.
mesh::MeshInput ToInput(const mesh::CellComplex& complex);

// Sharp edges of `rest` as vertex pairs (smaller first), edge order.
std::vector<std::array<int32_t, 2>> SharpPairs(const mesh::CellComplex& rest,
                                               const std::vector<uint8_t>& sharp);

// The identity source rows for vertices [0, n).
std::vector<std::vector<std::pair<int32_t, double>>> IdentitySources(int32_t n);

// Validates result.mesh (FromInput, positive volumes, manifold), keeps only
// the pairs of `sharp_pairs` (new ids) that are edges of the new mesh, in its
// edge order, and returns the result; errors are prefixed with `edit`.
absl::StatusOr<EditResult> Finish(absl::string_view edit, EditResult result,
                                  const std::vector<std::array<int32_t, 2>>& sharp_pairs);

// Manifold check of a built complex: every boundary edge lies in exactly two
// boundary faces, and the boundary faces around every boundary vertex form
// one fan (a single disk), so no two parts touch only along an edge or at a
// vertex. Errors name the vertex or edge and its position.
absl::Status CheckManifold(const mesh::CellComplex& complex);

// Cells grouped into components connected through shared faces; returns the
// component id per cell (numbered in order of their first cell).
std::vector<int32_t> CellComponents(const mesh::CellComplex& complex, int32_t* count);

// Unit normal of a loop (Newell's method) in `positions`; zero if degenerate.
Eigen::Vector3d LoopNormal(const Points& positions, std::span<const int32_t> loop);

// "1 cell" / "2 cells".
std::string Count(int64_t n, absl::string_view noun);

}  // namespace dynsolid::sculpt::internal
