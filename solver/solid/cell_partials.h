// What one control cell contributes to the control-space matrices of a
// build: the mass and damping (Mt, Dt) and the stiffness at rest (K0, and
// the per-cell corotation's matrices). Each is a CellSumSpec for SumByCell
// (cell_assembly.h), whose cells are made at once from their elements'
// quadrature points: the rows of all of a cell's points stacked into one
// matrix W, the partial its Gram matrix W^T W (models::Gram),
// no element matrix formed. (Element matrices per group, then B^T X B per
// element, took three times the flops where every element has its own
// shape, as after a local subdivision.)
#pragma once

#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/solid/cell_assembly.h"

namespace dynsolid::solid {

// An element's rows of the node matrix on the columns of its control
// cell's support: B (n x s_e), support[a] the cell column of column a
// (ascending); outside: the cell's other columns (ascending), where the
// element's rows of a cell matrix are zero.
struct ElementRows {
  std::vector<int32_t> support, outside;
  int nodes = 0;
  std::vector<double> values;  // B's entries (kept: a cell's B often fits the last one's room)
  Eigen::Map<const Eigen::MatrixXd> b() const {
    return {values.data(), nodes, static_cast<Eigen::Index>(support.size())};
  }
};

// What the mass and stiffness partials of a cell both read of its
// elements, made once per cell on the pool thread that makes them
// (SumByCells makes a cell's partials of every job on one thread): each
// element's node rows on the cell columns they touch (ElementRows) and,
// at its quadrature points, the rest volume dV = max(det J, 0) w and J^-T
// (zero where dV is 0), as the model computes them (a cubic element's J by
// sum factorization: the same up to rounding). Groups of several elements
// keep their points' data for the life of this object. `layout` and `nm`
// must outlive it; `threads`: the pool's size.
class CellPoints {
 public:
  struct Element {
    const ElementRows* rows;
    const double* dv;   // Q
    const double* jit;  // 9 Q: entry (k, c) of J_q^-T at [(3 k + c) Q + q]
  };
  CellPoints(const models::ElementLayout& layout, const subdivision::SparseMatrix& nm, int threads);
  ~CellPoints();
  CellPoints(const CellPoints&) = delete;
  CellPoints& operator=(const CellPoints&) = delete;
  // A cell's elements (its support and elements as CellSumSpec::make_cell
  // gets them), in order, on pool thread `thread`: made unless that
  // thread's last cell was this one. Valid until the thread's next call.
  const std::vector<Element>& Of(int thread, const std::vector<int32_t>& support,
                                 const std::vector<std::pair<int, int32_t>>& elements);
  // Whether cubic elements are on the 4-point rule, their products
  // sum-factorized (fem::CubicTensorProducts): CubicDerivatives applies.
  bool cubic_factorized() const;
  // The thread's last cell's distinct FEM nodes: their node-matrix rows
  // dense on the cell's columns (row major: count x support size), and
  // the row of node id `node` (one of the cell's elements' nodes).
  const double* NodeRows(int thread, int* count) const;
  int32_t NodeRow(int thread, int32_t node) const;
  // Of element i of the thread's last cell: N B (Q x s_e, column major),
  // made when first asked (or by CubicDerivatives) and kept for the cell.
  const double* Values(int thread, size_t i);
  // For a cubic element on the 4-point rule (fem::CubicTensorProducts):
  // the parametric derivatives of B into out (du, dv, dw: 3 x 64 x s_e),
  // making its N B on the way when not made yet (the same bits).
  void CubicDerivatives(int thread, size_t i, double* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Mt = sum_e B_e^T N^T diag(rho dV) N B_e (Dt alike, with the damping), B_e
// the element's rows of the node matrix on its control support: a cell's
// partial is W^T W, W stacking the rows sqrt(rho_q dV_q) N_q B_e of its
// elements' points. With damping, Dt's partial is r times Mt's where every
// point of the cell has one ratio r = damping / density, else the Gram
// matrix of the sqrt(damping dV) rows. `layout` and `points` must outlive
// this; the spec's functions point into it (not movable). `threads`: the
// pool SumByCell will run on.
class MassPartials {
 public:
  MassPartials(const models::ElementLayout& layout, bool has_damping, CellPoints& points,
               int threads);
  ~MassPartials();
  MassPartials(const MassPartials&) = delete;
  MassPartials& operator=(const MassPartials&) = delete;
  CellSumSpec& spec();

 private:
  struct Maker;
  std::unique_ptr<Maker> maker_;
};

// The cell partials of K0 = A^T K A (3 #control square, node-major DOFs
// 3 i + c) of the corotational model at rest, integrated at the quadrature
// points of its K = int B^T C B dV (isotropic C):
//
//   (E^T K E)(3a+c, 3b+d) = sum_q dV [lambda H(c,a) H(d,b) + mu H(d,a) H(c,b)
//                                     + mu delta_cd sum_k H(k,a) H(k,b)],
//
// E = B (x) I3, H_q = J_q^-T dN_q B the physical gradients of the control
// points' basis at point q (3 x S). W stacks the rows sqrt(dV mu) H_q(k, .)
// of all the cell's points (3S columns: column k S + a); its Gram matrix
// holds every mu sum above, and the lambda sums are r G when lambda = r mu
// at every point of the cell (one Poisson ratio), else the Gram matrix of
// the sqrt(dV lambda) rows. The same points, weights and clamped
// dV = max(det J, 0) as the model's K. Each partial also keeps, as its
// second matrix, the cell's deformation-gradient weights g_j (S x 3,
// cell_corotation.h), so that the per-cell corotation and K0 share their
// partials whichever made them. Lifetimes as MassPartials'.
class StiffnessPartials {
 public:
  StiffnessPartials(const models::ElementLayout& layout,
                    const models::CorotationalModel& corotational, CellPoints& points,
                    int threads);
  ~StiffnessPartials();
  StiffnessPartials(const StiffnessPartials&) = delete;
  StiffnessPartials& operator=(const StiffnessPartials&) = delete;
  CellSumSpec& spec();

 private:
  struct Maker;
  std::unique_ptr<Maker> maker_;
};

}  // namespace dynsolid::solid
