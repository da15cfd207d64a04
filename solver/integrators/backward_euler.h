// Backward Euler for stiff scenes (MODEL.md section 5), linearized at p(t)
// with the element frames held fixed for the step:
//
//   (Mt + h Dt + h^2 Kt) dv = h (F - h Kt v),   v = (p - p_prev) / h,
//   v' = v + dv,   p(t+h) = p + h v',
//
// F = A^T (f - g(A p)), Kt x = A^T K (A x) (+ penalty springs) applied
// matrix-free through a callback. Solved by preconditioned CG on all three
// components at once (Kt couples them); the preconditioner is the incomplete
// Cholesky factor of Mt + h Dt per component, or, after
// SetStiffnessPreconditioner(K0), the sparse LDL^T factor of
// Mt + h Dt + h^2 K0 with K0 the rest stiffness (the system itself at small
// rotations: a handful of iterations whatever the stiffness).
// Unconditionally stable for linear elasticity. Fixed control points keep
// their positions.
#pragma once

#include <functional>
#include <memory>

#include <Eigen/SparseCore>

#include "solver/integrators/cg.h"

namespace dynsolid::integrators {

class BackwardEuler {
 public:
  // out = Kt x (control space, #control by 3).
  using StiffnessOperator = std::function<void(const Points& x, Points& out)>;

  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h, std::vector<uint8_t> fixed);

  CgStats Step(const Points& p, const Points& p_prev, const Points& force,
               const StiffnessOperator& kt, Points& p_next, double tolerance, int max_iterations);

  // K0: 3 #control square, DOFs 3 i + c (the layout of a row-major
  // #control by 3 Points). Call after Setup.
  void SetStiffnessPreconditioner(const Eigen::SparseMatrix<double>& k0);

  double h() const { return h_; }

 private:
  void Apply(const StiffnessOperator& kt, const Points& x, Points& y);
  void Mask(Points& m) const;

  const SparseMatrix* mt_ = nullptr;
  const SparseMatrix* dt_ = nullptr;
  double h_ = 0;
  SparseMatrix md_;  // Mt + h Dt
  std::vector<uint8_t> fixed_;
  ColumnPreconditioner pre_;
  struct Flat;
  std::shared_ptr<Flat> flat_;
  void Precondition(const Points& r, Points& z) const;
  Points v_, rhs_, x_, r_, z_, p_, q_, tmp_;
};

}  // namespace dynsolid::integrators
