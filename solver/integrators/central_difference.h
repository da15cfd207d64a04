// The paper's explicit central-difference scheme (its Eq. 20) in
// control-point space:
//
//   (2 Mt + h Dt) p(t+h) = 2 h^2 F(t) + 4 Mt p(t) - (2 Mt - h Dt) p(t-h),
//   F(t) = A^T (f(t) - g(A p(t))),
//
// solved for the correction to the guess 2 p(t) - p(t-h). The matrix
// 2 Mt + h Dt is constant between set-ups (an edit, a paint of mass or
// damping, a change of sub-step or of the fixed set), so by default
// (Solve::kFactored) Setup factors it once on the free rows
// (ReducedCholesky: CHOLMOD) and a step is a forward and a back
// substitution for the three columns, exact to rounding (a 12^3-cell block
// at level 0, 2197 points with ~224 entries a row: the CG took 19
// iterations a step). Solve::kCg, the reference path and the fallback
// where the factor cannot be made, is preconditioned conjugate gradient
// warm-started from 2 p(t) - p(t-h): the unknown is the correction to that
// guess, so the relative tolerance (the paper's 1e-4) measures the force
// response. Its preconditioner is the matrix's exact Cholesky factor up to
// kExactRows control points, then CG stops after an iteration per column,
// incomplete Cholesky above.
// Stiffness is explicit: stable only for h < 2 / omega_max
// (the caller sub-steps). Fixed control points keep their positions.
//
// Step() reads p, p_prev and F, writes p_next; it allocates nothing.
#pragma once

#include "solver/integrators/cg.h"
#include "solver/integrators/reduced_cholesky.h"

namespace dynsolid::integrators {

class CentralDifference {
 public:
  static constexpr int64_t kExactRows = 256;
  enum class Solve { kFactored, kCg };
  // mt (and dt when not null) must outlive the integrator.
  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h, std::vector<uint8_t> fixed,
             Solve solve = Solve::kFactored);

  // Whether steps solve with the factor (kFactored asked and the factor
  // made) rather than CG.
  bool factored() const { return factor_.factored(); }
  const ReducedCholesky& factor() const { return factor_; }

  CgStats Step(const Points& p, const Points& p_prev, const Points& force, Points& p_next,
               double tolerance, int max_iterations);

  double h() const { return h_; }

 private:
  const SparseMatrix* mt_ = nullptr;
  const SparseMatrix* dt_ = nullptr;
  double h_ = 0;
  SparseMatrix lhs_;
  ConjugateGradient cg_;
  ReducedCholesky factor_;
  Points rhs_, tmp_, delta_;
  double lhs_diagonal_max_ = 0;
  // CG's absolute floor per column: this times the largest diagonal entry
  // of 2 Mt + h Dt times the column's norm of p (Step).
  static constexpr double kRoundingFloor = 1e-16;
};

}  // namespace dynsolid::integrators
