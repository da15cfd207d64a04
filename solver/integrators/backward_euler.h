// Backward Euler for stiff scenes (MODEL.md section 5), linearized at p(t)
// with the element frames held fixed for the step:
//
//   (Mt + h Dt + h^2 Kt) dv = h (F - h Kt v - Dt v),   v = (p - p_prev) / h,
//   v' = v + dv,   p(t+h) = p + h v',
//
// F = A^T (f - g(A p)), Kt x = A^T K (A x) (+ penalty springs) applied
// matrix-free through a callback. The right-hand side's F - h Kt v comes
// either from F and one more Kt product (Step with `force`), or folded from
// the caller in one evaluation (Step with `force_ahead`): with frames fixed
// the internal force is affine in p, so F - h Kt v = A^T (f - g_R(A (p + h v)))
// (the force evaluated ahead along the velocity), one element pass instead
// of two. Solved by preconditioned CG on all three
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
  // out = F - h Kt v for the step's velocity v (#control by 3; fixed rows of
  // v are zero): the right-hand side's force, folded.
  using ForceAhead = std::function<void(const Points& v, Points& out)>;

  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h, std::vector<uint8_t> fixed);

  // One step from (p, p_prev) to p_next. `force` = F (then F - h Kt v takes
  // one more Kt product) or `force_ahead` gives F - h Kt v directly; both
  // then solve the same system from dv = 0 with PCG to a relative residual
  // `tolerance` (of the right-hand side's norm), at most `max_iterations`.
  CgStats Step(const Points& p, const Points& p_prev, const Points& force,
               const StiffnessOperator& kt, Points& p_next, double tolerance, int max_iterations);
  CgStats Step(const Points& p, const Points& p_prev, const ForceAhead& force_ahead,
               const StiffnessOperator& kt, Points& p_next, double tolerance, int max_iterations);

  // The last step's velocity v, its change dv and Kt dv (summed from the CG's
  // own Kt products, no extra evaluation): a caller's energy bookkeeping
  // (E(p + h v + h dv) of a quadratic E from E and its gradient at p + h v).
  // Fixed rows of v and dv are zero.
  const Points& last_v() const { return v_; }
  const Points& last_dv() const { return x_; }
  const Points& last_kt_dv() const { return kx_; }

  // K0: 3 #control square, DOFs 3 i + c (the layout of a row-major
  // #control by 3 Points). Call after Setup.
  void SetStiffnessPreconditioner(const Eigen::SparseMatrix<double>& k0);

  double h() const { return h_; }

 private:
  void Apply(const StiffnessOperator& kt, const Points& x, Points& y);
  // Solves from rhs_ (set by the Step overloads) and writes p_next.
  CgStats Solve(const Points& p, const StiffnessOperator& kt, Points& p_next, double tolerance,
                int max_iterations);
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
  Points v_, rhs_, x_, r_, z_, p_, q_, tmp_, kx_;
};

}  // namespace dynsolid::integrators
