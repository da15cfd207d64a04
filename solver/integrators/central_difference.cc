#include <algorithm>
#include "solver/integrators/central_difference.h"

namespace dynsolid::integrators {

void CentralDifference::Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h,
                              std::vector<uint8_t> fixed, Solve solve) {
  mt_ = mt;
  dt_ = dt;
  h_ = h;
  lhs_ = 2.0 * (*mt);
  if (dt != nullptr) lhs_ += h * (*dt);
  factor_ = ReducedCholesky();
  if (solve == Solve::kFactored && factor_.Factor(lhs_, fixed)) {
    // No CG set-up (its preconditioner would be a second factor).
    cg_ = ConjugateGradient();
  } else {
    factor_ = ReducedCholesky();
    cg_.Setup(&lhs_, std::move(fixed),
              lhs_.rows() <= kExactRows ? Preconditioner::kDirect
                                        : Preconditioner::kIncompleteCholesky);
  }
  lhs_diagonal_max_ = 0;
  for (int64_t i = 0; i < lhs_.rows(); ++i) lhs_diagonal_max_ = std::max(lhs_diagonal_max_, lhs_.coeff(i, i));
  rhs_.setZero(mt->rows(), 3);
  tmp_.setZero(mt->rows(), 3);
  delta_.setZero(mt->rows(), 3);
}

CgStats CentralDifference::Step(const Points& p, const Points& p_prev, const Points& force,
                                Points& p_next, double tolerance, int max_iterations) {
  // Warm start p~ = 2 p - p_prev and solve for the correction Delta:
  //   (2 Mt + h Dt) Delta = 2 h^2 F - 2 h Dt (p - p_prev),
  // so the relative tolerance applies to what the forces change, not to
  // the (much larger) inertial part of the right-hand side.
  rhs_ = (2.0 * h_ * h_) * force;
  if (dt_ != nullptr) {
    tmp_ = p - p_prev;
    delta_.noalias() = *dt_ * tmp_;
    rhs_ -= (2.0 * h_) * delta_;
  }
  if (factor_.factored()) {
    // Exact to rounding: no iterations, no residual to report.
    factor_.Solve(rhs_, delta_);
    p_next = 2.0 * p - p_prev + delta_;
    return CgStats{};
  }
  delta_.setZero();
  // A residual this small moves no control point by more than rounding
  // of its coordinates (about 1e-16 of them): at rest the forces are
  // rounding noise, and 1e-4 of noise is not worth iterating for.
  double floor[3];
  for (int c = 0; c < 3; ++c) floor[c] = kRoundingFloor * lhs_diagonal_max_ * p.col(c).norm();
  const CgStats stats = cg_.Solve(rhs_, delta_, tolerance, max_iterations, floor);
  p_next = 2.0 * p - p_prev + delta_;
  return stats;
}

}  // namespace dynsolid::integrators
