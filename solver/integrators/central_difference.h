// The paper's explicit central-difference scheme (its Eq. 20) in
// control-point space:
//
//   (2 Mt + h Dt) p(t+h) = 2 h^2 F(t) + 4 Mt p(t) - (2 Mt - h Dt) p(t-h),
//   F(t) = A^T (f(t) - g(A p(t))),
//
// solved by preconditioned conjugate gradient warm-started from
// 2 p(t) - p(t-h): the unknown is the correction to that guess, so the
// relative tolerance (the paper's 1e-4) measures the force response. The
// preconditioner is the matrix's exact Cholesky factor up to kExactRows
// control points, then CG stops after an iteration per column (torus, 108
// points: 15 iterations a step to 3, its solve 0.19 to 0.024 ms; nozzle,
// 220: 12 to 3, 0.38 to 0.11 ms; the chair's set-up after an edit 2-3 ms
// to 0.7-1), incomplete Cholesky above (the bridge's 392 points converge
// in an iteration with it, and the dense solve took 0.20 ms to its 0.024).
// Stiffness is explicit: stable only for h < 2 / omega_max
// (the caller sub-steps). Fixed control points keep their positions.
//
// Step() reads p, p_prev and F, writes p_next; it allocates nothing.
#pragma once

#include "solver/integrators/cg.h"

namespace dynsolid::integrators {

class CentralDifference {
 public:
  static constexpr int64_t kExactRows = 256;
  // mt (and dt when not null) must outlive the integrator.
  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h, std::vector<uint8_t> fixed);

  CgStats Step(const Points& p, const Points& p_prev, const Points& force, Points& p_next,
               double tolerance, int max_iterations);

  double h() const { return h_; }

 private:
  const SparseMatrix* mt_ = nullptr;
  const SparseMatrix* dt_ = nullptr;
  double h_ = 0;
  SparseMatrix lhs_;
  ConjugateGradient cg_;
  Points rhs_, tmp_, delta_;
  double lhs_diagonal_max_ = 0;
  // CG's absolute floor per column: this times the largest diagonal entry
  // of 2 Mt + h Dt times the column's norm of p (Step).
  static constexpr double kRoundingFloor = 1e-16;
};

}  // namespace dynsolid::integrators
