// The corotational model with one frame per control cell
// (solver.corotation: CONTROL_CELL), applied in control-point space.
//
// docs/model.md 4b rotates each finite element's stiffness by the element's own
// frame, so every step passes over all elements (64 per control cell at two
// levels, 64 quadrature points each). Here the stiffness of a control cell
// is summed once, at rest, over its elements and mapped to its control
// points:
//
//   K_c = sum over the cell's elements of E_e^T K_e E_e   (3 S square),
//
// S the control points the cell's elements depend on (64 for a regular cell
// at two levels), E_e the element's rows of the node matrix on them (the
// same partials backward Euler's K0 is summed from: solid/cell_assembly.h).
// A step then needs, per cell, one frame and one product:
//
//   F_c = sum_j x_j g_j^T,   R_c = polar factor of F_c,
//   u_c = R_c^T (x - xbar) - (X - Xbar),   g_c = R_c K_c u_c,
//   energy = 1/2 sum_c u_c . K_c u_c,
//
// F_c the cell's deformation gradient averaged over its elements (each
// element's at its centre, weighted by its rest volume): g_j = sum_e V_e
// sum_i B_e(i, j) grad N_i(centre_e) / sum_e V_e, made at build time, so
// that F_c = I at rest and F_c = Q for any rigid motion (sum_j g_j = 0).
// xbar is the cell's control points' centroid weighted by their diagonal
// stiffness in K_c (any point would do: K_c ignores translations). Frames
// are found afresh every step (no warm start, so no state: a scaled Newton
// polar iteration, quadratically convergent from any F with det F > 0; an
// SVD otherwise).
//
// Properties: for small displacements R_c = I + O(u) and g = K u to first
// order, the linear stiffness A^T K A of the element model (so stable step,
// static answers and small vibrations are the same); rigid motion gives
// exactly no force and no energy; each cell's forces sum to zero (linear
// momentum). What it gives up: a cell bent through a large angle is rotated
// by its average frame rather than element by element.
//
// Backward Euler (docs/model.md 5) holds the frames of p(t) for a step:
// UpdateFrames(p) finds them as Forces(p) does, AffineForces(x) is the force
// with them held (affine in x; AffineForces(p) after UpdateFrames(p) equals
// Forces(p) bit for bit) and ApplyLinearized(v) = sum_c E_c^T R_c K_c R_c^T
// (v_c - vbar_c), the step's Kt. The held frames are a function of the
// positions they were found at, so they are no state of their own.
//
// Cells whose partials are equal (congruent cells of one material: the
// interior of a block, the legs of a chair) share one K_c and are applied
// together as one matrix product. The cells are split into kForceParts
// fixed parts summed in part order: results do not depend on the thread
// count.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "solver/common/worker_pool.h"
#include "solver/mesh/points.h"

namespace dynsolid::models {

// Plasticity's hook into the per-cell corotation (material/plasticity.h
// implements it): each cell's rest shape moved by offsets u_p (3 per support
// entry, in the order of the cell's support, rest frame):
//
//   u_c = R_c^T (x - xbar) - (X - Xbar) - u_p,   R_c = polar(F_c F_p^-1),
//   F_p = I + sum_j u_pj g_j^T,
//
// so that the plastically deformed rest shape, moved rigidly, carries no
// force. A force pass that holds frames (Forces) calls Flow for each cell
// after its force, on the pool's threads: Flow may change that cell's
// offsets only.
class CellFlow {
 public:
  virtual ~CellFlow() = default;
  // All cells' offsets (null: none yet, all zero).
  virtual const double* offsets() const = 0;
  // Whether this pass flows (a flow step is armed).
  virtual bool flowing() const = 0;
  // Whether cell `cell` may differ from elastic: its material yields or its
  // offsets are not all zero (the others skip the plastic frame and offsets).
  virtual bool plastic(int32_t cell) const = 0;
  // Cell `cell`'s elastic local displacement u and K_c u (3 S each).
  virtual void Flow(int32_t cell, const double* u, const double* ku) = 0;
};

class CellCorotation {
 public:
  struct Cell {
    std::vector<int32_t> support;                 // ascending control points
    std::shared_ptr<const Eigen::MatrixXd> k;     // 3 S square, DOF 3 a + c
    std::vector<Eigen::Vector3d> gradient;        // g_a per support point (above)
  };

  // rest: the control points at rest (#control by 3).
  CellCorotation(std::vector<Cell> cells, const Points& rest, WorkerPool& pool);

  // g = sum_c E_c^T g_c: the internal forces on the control points (#control
  // by 3; the force acting on the solid is -g) at control positions p,
  // written over g. Holds the frames of p for the calls below. Returns the
  // strain energy. Allocates nothing after the first call.
  double Forces(const Points& p, Points& g);
  // The same without holding the frames (a query that leaves the model as
  // it was).
  double ForcesAt(const Points& p, Points& g);
  // Backward Euler's calls (above).
  void UpdateFrames(const Points& p);
  double AffineForces(const Points& x, Points& g);
  void ApplyLinearized(const Points& v, Points& out);
  // out = sum_c E_c^T K_c E_c v: the stiffness at rest (all frames the
  // identity), A^T K A of the element model to rounding, for the
  // stable-step estimate. Leaves the model as it was; on `pool` (null: this
  // thread alone), so it may run beside the calls above.
  void ApplyRest(const Points& v, Points& out, WorkerPool* pool) const;


  void set_pool(WorkerPool& pool) { pool_ = &pool; }
  // The plastic flow hook (null: elastic; the default).
  void set_flow(CellFlow* flow) { flow_ = flow; }
  // A cell's support: where its entries start among all cells' (the
  // offsets' index / 3), how many, and its points' rest positions about the
  // cell's weighted centre (3 per entry).
  int32_t support_first(int32_t cell) const { return cells_[cell].first; }
  int32_t support_size(int32_t cell) const { return cells_[cell].size; }
  int64_t support_entries() const { return static_cast<int64_t>(support_.size()); }
  const int32_t* support(int32_t cell) const { return support_.data() + cells_[cell].first; }
  const double* rest_local(int32_t cell) const {
    return rest_local_.data() + 3 * static_cast<int64_t>(cells_[cell].first);
  }
  // 1/2 u . K_c u for a local displacement u of cell `cell` (3 S values).
  double Energy(int32_t cell, const double* u) const;
  int32_t cells() const { return static_cast<int32_t>(cells_.size()); }
  int32_t distinct_matrices() const { return static_cast<int32_t>(matrices_.size()); }
  int64_t matrix_bytes() const { return matrix_bytes_; }

 private:
  struct CellData {
    int32_t matrix = 0;    // index into matrices_
    int32_t first = 0;     // its support's range in support_
    int32_t size = 0;
  };
  // Cells of one part with one matrix: applied as one product.
  struct Batch {
    int32_t matrix = 0;
    std::vector<int32_t> cells;
  };
  Eigen::Matrix3d FrameOf(const CellData& c, const Points& p, Eigen::Vector3d& centre) const;
  Eigen::Vector3d CentreOf(const CellData& c, const Points& p) const;
  // How a pass gets its frames and local displacements.
  enum class Mode {
    kFind,     // frames found at x, not held; u = R^T (x - xbar) - X
    kHold,     // found at x and held; u as kFind
    kFrames,   // found and held, no product
    kAffine,   // held frames; u as kFind
    kLinear,   // held frames; u = R^T (x - xbar)
    kRest,     // identity frames; u = x - xbar
  };
  struct Scratch;
  // One pass in `mode` on `pool`, with per-part `scratch`; `held` the frames
  // held (read or written as mode says).
  double Run(const Points& x, Points& g, Mode mode, std::vector<Scratch>& scratch,
             std::vector<Eigen::Matrix3d>* held, WorkerPool& pool) const;
  std::vector<Scratch> MakeScratch(int64_t points) const;

  WorkerPool* pool_;
  CellFlow* flow_ = nullptr;
  std::vector<CellData> cells_;
  std::vector<int32_t> support_;      // all cells' supports, concatenated
  std::vector<double> weight_;        // w_j, normalized per cell, same order
  std::vector<double> rest_local_;    // X_j - Xbar, 3 per support entry
  std::vector<double> gradient_;      // g_j, 3 per support entry
  std::vector<std::shared_ptr<const Eigen::MatrixXd>> matrices_;
  std::vector<std::vector<Batch>> parts_;
  std::vector<Eigen::Matrix3d> held_;  // per cell: the frames backward Euler holds
  int64_t matrix_bytes_ = 0;
  int max_side_ = 0, max_batch_ = 1;
  std::vector<Scratch> scratch_;
};

// Per part: its force sum over all control points and its scratch.
struct CellCorotation::Scratch {
  Points f;
  Eigen::MatrixXd u, y;
  std::vector<Eigen::Matrix3d> frames;
  double energy = 0;
};

}  // namespace dynsolid::models
