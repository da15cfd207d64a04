#include "solver/integrators/cg.h"

#include <algorithm>
#include <cmath>

#include <optional>

#include <Eigen/Cholesky>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCholesky>

namespace dynsolid::integrators {

struct ColumnPreconditioner::Ic {
  Eigen::IncompleteCholesky<double, Eigen::Lower, Eigen::AMDOrdering<int>> factor;
  mutable Eigen::VectorXd in, out;
  std::vector<uint8_t> fixed;
};

struct ColumnPreconditioner::Direct {
  std::optional<Eigen::LLT<Eigen::MatrixXd>> llt;
  std::optional<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>> ldlt;
  std::vector<uint8_t> fixed;

  // S with the fixed rows and columns made the identity, factored; false
  // where it is not positive definite (or too large to factor here).
  bool Factor(const SparseMatrix& s, const std::vector<uint8_t>& fixed_rows) {
    const int64_t n = s.rows();
    if (n > kDirectRows) return false;
    fixed = fixed_rows;
    auto for_each_entry = [&](auto&& put) {
      for (int64_t i = 0; i < n; ++i) {
        if (fixed[i]) {
          put(i, i, 1.0);
          continue;
        }
        for (SparseMatrix::InnerIterator it(s, i); it; ++it) {
          if (fixed[it.col()]) continue;
          put(i, static_cast<int64_t>(it.col()), it.value());
        }
      }
    };
    if (n <= kDenseRows) {
      // Written straight in, no triplets.
      Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
      for_each_entry([&](int64_t i, int64_t j, double v) { m(i, j) = v; });
      llt.emplace(m);
      return llt->info() == Eigen::Success;
    }
    std::vector<Eigen::Triplet<double, int32_t>> t;
    t.reserve(static_cast<size_t>(s.nonZeros()));
    for_each_entry([&](int64_t i, int64_t j, double v) {
      t.emplace_back(static_cast<int32_t>(i), static_cast<int32_t>(j), v);
    });
    Eigen::SparseMatrix<double> m(n, n);
    m.setFromTriplets(t.begin(), t.end());
    ldlt.emplace(m);
    return ldlt->info() == Eigen::Success;
  }
};

ColumnPreconditioner::ColumnPreconditioner() = default;
ColumnPreconditioner::~ColumnPreconditioner() = default;
ColumnPreconditioner::ColumnPreconditioner(ColumnPreconditioner&&) noexcept = default;
ColumnPreconditioner& ColumnPreconditioner::operator=(ColumnPreconditioner&&) noexcept = default;

void ColumnPreconditioner::Setup(const SparseMatrix& s, const std::vector<uint8_t>& fixed,
                                 Preconditioner kind) {
  const int64_t n = s.rows();
  inv_diag_ = s.diagonal();
  for (int64_t i = 0; i < n; ++i) {
    inv_diag_[i] = inv_diag_[i] > 0 && !fixed[i] ? 1.0 / inv_diag_[i] : 0.0;
  }
  ic_.reset();
  direct_.reset();
  if (kind == Preconditioner::kDirect) {
    auto direct = std::make_unique<Direct>();
    if (direct->Factor(s, fixed)) {
      direct_ = std::move(direct);
      return;
    }
  }
  if (kind == Preconditioner::kJacobi) return;
  // The reduced matrix: fixed rows and columns replaced by identity.
  Eigen::SparseMatrix<double> reduced = s;
  for (int k = 0; k < reduced.outerSize(); ++k) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(reduced, k); it; ++it) {
      if (fixed[it.row()] || fixed[it.col()]) it.valueRef() = it.row() == it.col() ? 1.0 : 0.0;
    }
  }
  ic_ = std::make_unique<Ic>();
  ic_->factor.compute(reduced);
  if (ic_->factor.info() != Eigen::Success) {
    ic_.reset();  // fall back to Jacobi
    return;
  }
  ic_->in.resize(n);
  ic_->out.resize(n);
  ic_->fixed = fixed;
}

void ColumnPreconditioner::Apply(const Points& r, Points& z) const {
  if (direct_ != nullptr) {
    if (direct_->llt.has_value()) {
      z = direct_->llt->solve(r);
    } else {
      z = direct_->ldlt->solve(Eigen::MatrixXd(r));
    }
    for (int64_t i = 0; i < z.rows(); ++i) {
      if (direct_->fixed[i]) z.row(i).setZero();
    }
    return;
  }
  if (!ic_) {
    z = inv_diag_.asDiagonal() * r;
    return;
  }
  for (int c = 0; c < 3; ++c) {
    ic_->in = r.col(c);
    ic_->out = ic_->factor.solve(ic_->in);
    z.col(c) = ic_->out;
  }
  for (int64_t i = 0; i < z.rows(); ++i) {
    if (ic_->fixed[i]) z.row(i).setZero();
  }
}

ConjugateGradient::ConjugateGradient() = default;
ConjugateGradient::~ConjugateGradient() = default;
ConjugateGradient::ConjugateGradient(ConjugateGradient&&) noexcept = default;
ConjugateGradient& ConjugateGradient::operator=(ConjugateGradient&&) noexcept = default;

void ConjugateGradient::Setup(const SparseMatrix* s, std::vector<uint8_t> fixed,
                              Preconditioner preconditioner) {
  s_ = s;
  const int64_t n = s->rows();
  fixed_ = fixed.empty() ? std::vector<uint8_t>(n, 0) : std::move(fixed);
  any_fixed_ = std::find(fixed_.begin(), fixed_.end(), 1) != fixed_.end();
  for (Points* m : {&r_, &z_, &p_, &q_, &b0_}) m->setZero(n, 3);
  pre_.Setup(*s, fixed_, preconditioner);
}

void ConjugateGradient::MaskFixed(Points& m) const {
  if (!any_fixed_) return;
  for (int64_t i = 0; i < m.rows(); ++i) {
    if (fixed_[i]) m.row(i).setZero();
  }
}

CgStats ConjugateGradient::Solve(const Points& b, Points& x, double tolerance,
                                 int max_iterations, const double* floor) {
  CgStats stats;
  // A zero start (the integrators' usual one) needs none of the products
  // with x below: they would be zero.
  const bool x_zero = (x.array() == 0.0).all();
  // Right-hand side of the reduced system: b_f - S_fc x_c.
  double bnorm2[3];
  if (any_fixed_ && !x_zero) {
    b0_ = x;
    for (int64_t i = 0; i < b0_.rows(); ++i) {
      if (!fixed_[i]) b0_.row(i).setZero();
    }
    q_.noalias() = *s_ * b0_;
    b0_ = b - q_;
    MaskFixed(b0_);
  } else {
    b0_ = b;
    MaskFixed(b0_);
  }
  for (int c = 0; c < 3; ++c) bnorm2[c] = b0_.col(c).squaredNorm();
  // Done at this squared residual: the relative test, or the floor.
  double stop2[3];
  for (int c = 0; c < 3; ++c) {
    stop2[c] = tolerance * tolerance * bnorm2[c];
    if (floor != nullptr) stop2[c] = std::max(stop2[c], floor[c] * floor[c]);
  }

  if (x_zero) {
    r_ = b;
  } else {
    q_.noalias() = *s_ * x;
    r_ = b - q_;
  }
  MaskFixed(r_);
  double rz[3] = {0, 0, 0}, rr[3];
  bool done[3];
  int iters[3] = {0, 0, 0};
  for (int c = 0; c < 3; ++c) {
    rr[c] = r_.col(c).squaredNorm();
    done[c] = rr[c] <= stop2[c] || bnorm2[c] == 0.0;
  }
  // (A start that already meets the tolerance needs no preconditioning.)
  if (!(done[0] && done[1] && done[2])) {
    Precondition();
    p_ = z_;
    for (int c = 0; c < 3; ++c) rz[c] = r_.col(c).dot(z_.col(c));
  }
  for (int it = 0; it < max_iterations && !(done[0] && done[1] && done[2]); ++it) {
    q_.noalias() = *s_ * p_;
    MaskFixed(q_);
    for (int c = 0; c < 3; ++c) {
      if (done[c]) continue;
      const double pq = p_.col(c).dot(q_.col(c));
      if (pq <= 0.0) {  // breakdown (not SPD on this column): stop it
        done[c] = true;
        continue;
      }
      const double alpha = rz[c] / pq;
      x.col(c) += alpha * p_.col(c);
      r_.col(c) -= alpha * q_.col(c);
      rr[c] = r_.col(c).squaredNorm();
      ++iters[c];
      if (rr[c] <= stop2[c]) done[c] = true;
    }
    if (done[0] && done[1] && done[2]) break;
    Precondition();
    for (int c = 0; c < 3; ++c) {
      if (done[c]) continue;
      const double rz_new = r_.col(c).dot(z_.col(c));
      p_.col(c) = z_.col(c) + (rz_new / rz[c]) * p_.col(c);
      rz[c] = rz_new;
    }
  }
  for (int c = 0; c < 3; ++c) {
    stats.iterations += iters[c];
    stats.max_iterations = std::max(stats.max_iterations, iters[c]);
    // (A column below the floor is solved: its relative residual, of noise, is not reported.)
    const bool below_floor = floor != nullptr && rr[c] <= floor[c] * floor[c];
    const double rel = bnorm2[c] > 0 && !below_floor ? std::sqrt(rr[c] / bnorm2[c]) : 0.0;
    stats.relative_residual = std::max(stats.relative_residual, rel);
    stats.converged &= rel <= tolerance || bnorm2[c] == 0.0 || rr[c] <= stop2[c];
  }
  return stats;
}

}  // namespace dynsolid::integrators
