// Control-space matrices (the mass Mt and damping Dt, backward Euler's K0)
// summed control cell by control cell, each cell's partial sum remembered
// under a key of everything it is made of, so that the next build (a paint,
// a topology edit) makes anew only the cells that changed.
//
// Every such matrix is a sum of element blocks E_e^T X_e E_e, E_e the
// element's rows of the node matrix on its control support. Here it is
// summed in a fixed order: per control cell, a partial over the cell's
// support that the caller makes from its elements (kind order, then block
// order) at once (the Gram matrix of their points' rows, for the mass and
// K0); then the partials in cell order. A cell's partial is a function of
// its key alone: its elements' group contents (the caller's group key:
// rest shape, material, anything the element's X depends on) and node
// rows, the control points numbered within the cell's support. A
// renumbering that keeps their order (cells deleted, points appended)
// keeps the key. So a matrix summed with the partials of an earlier build
// has the bits of one summed from scratch, and a solid rebuilt from its
// scene (crash recovery) equals the edited one.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "solver/common/hash128.h"
#include "solver/common/worker_pool.h"
#include "solver/models/element_blocks.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {

// The partials of one build, by cell key, for the next.
struct CellPartials {
  // A cell's partial over its support (S points): outputs matrices of dofs S square.
  std::unordered_map<Key128, std::shared_ptr<const std::vector<Eigen::MatrixXd>>, Key128Hash> by_key;
  int32_t made = 0;   // distinct partials made in this build (not carried)
  double bytes = 0;
};

// The cells' supports and geometry keys (their elements' kinds and node
// rows), the same for every sum over one node matrix and layout: made by
// the first SumByCell given it, taken by the next (a build's mass and
// stiffness sums).
struct CellGeometry {
  std::vector<std::vector<int32_t>> supports;
  std::vector<Key128> keys;
};

struct CellSumSpec {
  int dofs = 1;     // rows per control point (1: mass; 3: stiffness, node-major 3 i + c)
  int outputs = 1;  // matrices summed side by side (mass and damping: 2)
  uint64_t salt = 0;  // what else the blocks depend on (settings)
  // Optional: shared between the sums of one node matrix and layout.
  CellGeometry* geometry = nullptr;
  // Hand each cell's support and partial out (CellSums::supports,
  // partials) instead of summing them.
  bool per_cell = false;
  // A key of everything the blocks of a group's elements depend on besides
  // their node rows.
  std::function<Key128(int kind, int32_t group)> group_key;
  // A cell's whole partial (outputs matrices of dofs S square, given
  // sized but not cleared: every entry is to be written) made at once from
  // its support and elements (kind, index in block), on
  // pool thread `thread`; a function of the cell's key alone. It may
  // append more matrices, which the partial keeps (carried with it).
  std::function<void(int thread, const std::vector<int32_t>& support,
                     const std::vector<std::pair<int, int32_t>>& elements,
                     std::vector<Eigen::MatrixXd>& partial)>
      make_cell;
};

// The sums, dense or sparse (dofs #control square; sparse: row-major,
// compressed, the entries some cell's partial has non-zero).
struct CellSums {
  std::vector<Eigen::MatrixXd> matrices;
  std::vector<subdivision::SparseMatrix> sparse;
  // With CellSumSpec::per_cell, per control cell: its support (ascending
  // control points) and its partial (cells of one key share one).
  std::vector<std::vector<int32_t>> supports;
  std::vector<std::shared_ptr<const std::vector<Eigen::MatrixXd>>> partials;
};

// Sums the layout's element blocks as above into out (dense when `dense`).
// previous: the partials of an earlier build (null: none). Returns this
// build's partials (to carry to the next unless bytes is above what it is
// worth keeping: kMaxCarriedBytes).
std::shared_ptr<CellPartials> SumByCell(const subdivision::SparseMatrix& nm,
                                        const models::ElementLayout& layout,
                                        const std::vector<int32_t>& control_cell,
                                        int32_t control_cells, const CellSumSpec& spec,
                                        const CellPartials* previous, WorkerPool& pool, bool dense,
                                        CellSums& out);

// One family of matrices summed by cell (SumByCells): what it sums, the
// partials of an earlier build (null: none), and where the sums go.
struct CellSumJob {
  const CellSumSpec* spec = nullptr;
  const CellPartials* previous = nullptr;
  bool dense = false;
  CellSums* out = nullptr;
  // Set by SumByCells: this build's partials (to carry to the next unless
  // bytes is above kMaxCarriedBytes).
  std::shared_ptr<CellPartials> made;
};

// Several sums over one node matrix and layout, as SumByCell each, with
// their new partials made in one pass over the cells: a cell's partials of
// every job one after another, in job order, on one pool thread (so that
// makers sharing what they read of a cell, CellPoints, read it once).
// `beside`: the caller's jobs, sharing nothing with the sums, each run
// once in that pass by the pool thread that reaches it first (the first
// parts of the pass, before the costliest cell).
void SumByCells(const subdivision::SparseMatrix& nm, const models::ElementLayout& layout,
                const std::vector<int32_t>& control_cell, int32_t control_cells,
                std::vector<CellSumJob>& jobs, WorkerPool& pool,
                const std::vector<std::function<void()>>& beside = {});

// Partials above this many bytes are not carried to the next build.
inline constexpr double kMaxCarriedBytes = 64.0 * 1048576.0;

}  // namespace dynsolid::solid
