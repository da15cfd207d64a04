// MacCracken-Joy subdivision of cell complexes (docs/model.md section 2).
//
// One level maps a complex to a finer one and returns the subdivision
// matrix A_l (rows: new vertices, columns: old vertices; every row sums to
// 1). L levels compose A = A_L ... A_1. Build once per topology change;
// never re-subdivide per time step: positions follow as d = A p.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include <Eigen/SparseCore>

#include "absl/status/statusor.h"
#include "solver/common/sparse_matrix.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::subdivision {

using SparseMatrix = dynsolid::SparseMatrix;  // Eigen's, with a real move (common/sparse_matrix.h)

struct SubdivisionOptions {
  // Per-edge sharp tags of the input complex (empty: none sharp).
  std::vector<uint8_t> sharp_edges;
  // Cells to refine (empty: all). With a subset this is local subdivision:
  // unrefined cells keep their vertices, and faces and edges they share
  // with refined cells are split at their centroid and midpoint, so their
  // shape does not change (reading of docs/model.md section 2).
  std::vector<int32_t> cells;
  // Also check cell volumes of the result (tests; off on hot paths).
  bool validate_geometry = false;
};

// The result of one level. New vertex numbering for uniform subdivision:
// [old vertices | edge points | face points | cell points].
struct Level {
  mesh::CellComplex fine;
  SparseMatrix a;                       // fine vertices x coarse vertices
  std::vector<int32_t> parent_cell;     // fine cell -> coarse cell
  std::vector<uint8_t> sharp_edges;     // per fine edge
};

absl::StatusOr<Level> SubdivideOnce(const mesh::CellComplex& coarse,
                                    const SubdivisionOptions& options);

// A row-major sparse matrix from its compressed rows (outer: rows + 1
// offsets into inner and values; columns ascending within a row).
SparseMatrix FromCsr(int32_t rows, int32_t cols, const std::vector<int32_t>& outer,
                     const std::vector<int32_t>& inner, const std::vector<double>& values);

// a * b for row-major sparse matrices, row by row with a dense accumulator
// (deterministic summation order; no storage-order conversions).
SparseMatrix MultiplyRowMajor(const SparseMatrix& a, const SparseMatrix& b);

// L uniform levels on top of a control complex.
struct Hierarchy {
  std::shared_ptr<const mesh::CellComplex> control;
  std::shared_ptr<const mesh::CellComplex> fine;  // == control when levels = 0
  int levels = 0;
  SparseMatrix a;                       // fine vertices x control vertices
  std::vector<int32_t> control_cell;    // fine cell -> control cell
  std::vector<uint8_t> sharp_edges;     // per fine edge
};

// beside_last (optional): called once with the finest complex, on this
// thread, while the last level's matrix product runs on another (work of
// the caller's that needs the complex but not A); with fewer than two
// levels (no product) after the rest.
absl::StatusOr<Hierarchy> Subdivide(
    std::shared_ptr<const mesh::CellComplex> control, int levels,
    std::vector<uint8_t> control_sharp_edges,
    const std::function<void(const mesh::CellComplex&)>& beside_last = nullptr);

// Tags of edges given by vertex pairs; InvalidArgument names a pair that is
// not an edge of `complex`.
absl::StatusOr<std::vector<uint8_t>> SharpEdgesFromPairs(
    const mesh::CellComplex& complex, const std::vector<std::array<int32_t, 2>>& pairs);

// Boundary edges whose two boundary faces meet at a dihedral angle sharper
// than `degrees` (deviation from flat) are tagged in `tags` (sized to edges).
void TagCreases(const mesh::CellComplex& complex, double degrees, std::vector<uint8_t>& tags);

}  // namespace dynsolid::subdivision
