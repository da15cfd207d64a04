// What one control cell contributes to the control-space matrices of a
// build: the mass and damping (Mt, Dt) and the stiffness at rest (K0, and
// the per-cell corotation's matrices). Each is a CellSumSpec for SumByCell
// (cell_assembly.h), whose cells are made at once from their elements'
// quadrature points: the rows of all of a cell's points stacked into one
// matrix W, the partial its Gram matrix W^T W (one symmetric rank update),
// no element matrix formed. (Element matrices per group, then B^T X B per
// element, took three times the flops where every element has its own
// shape, as after a local subdivision.)
#pragma once

#include <memory>

#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/solid/cell_assembly.h"

namespace dynsolid::solid {

// Mt = sum_e B_e^T N^T diag(rho dV) N B_e (Dt alike, with the damping), B_e
// the element's rows of the node matrix on its control support: a cell's
// partial is W^T W, W stacking the rows sqrt(rho_q dV_q) N_q B_e of its
// elements' points (and a second W of sqrt(damping dV) rows with damping).
// `layout` and `nm` must outlive this; the spec's functions point into it
// (not movable). `threads`: the pool SumByCell will run on.
class MassPartials {
 public:
  MassPartials(const models::ElementLayout& layout, const subdivision::SparseMatrix& nm,
               bool has_damping, int threads);
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
                    const models::CorotationalModel& corotational,
                    const subdivision::SparseMatrix& nm, int threads);
  ~StiffnessPartials();
  StiffnessPartials(const StiffnessPartials&) = delete;
  StiffnessPartials& operator=(const StiffnessPartials&) = delete;
  CellSumSpec& spec();

 private:
  struct Maker;
  std::unique_ptr<Maker> maker_;
};

}  // namespace dynsolid::solid
