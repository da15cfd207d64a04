#include "solver/integrators/backward_euler.h"

#include <algorithm>
#include <cassert>
#include <climits>
#include <cmath>


namespace dynsolid::integrators {

struct BackwardEuler::Flat {
  ReducedCholesky factor;  // on the free DOFs
};

std::shared_ptr<BackwardEuler::Flat> BackwardEuler::Factor(const SparseMatrix& md,
                                                          const std::vector<uint8_t>& fixed,
                                                          double h, const SparseMatrix& k0) {
  const int32_t n = static_cast<int32_t>(md.rows());
  // P = md (x) I3 + h^2 K0's upper triangle (all ReducedCholesky reads),
  // row by row: row 3 r + a merges md's row r (its columns 3 c + a) with
  // K0's row 3 r + a, an entry in both summed as md + h^2 k.
  const double h2 = h * h;
  std::vector<int32_t> outer(static_cast<size_t>(3 * n) + 1, 0), inner;
  std::vector<double> values;
  inner.reserve(static_cast<size_t>(k0.nonZeros()));
  values.reserve(static_cast<size_t>(k0.nonZeros()));
  for (int32_t r = 0; r < n; ++r) {
    for (int a = 0; a < 3; ++a) {
      const int32_t row = 3 * r + a;
      SparseMatrix::InnerIterator m(md, r), k(k0, row);
      while (m && 3 * m.col() + a < row) ++m;
      while (k && k.col() < row) ++k;
      while (m || k) {
        const int32_t mc = m ? static_cast<int32_t>(3 * m.col() + a) : INT32_MAX;
        const int32_t kc = k ? static_cast<int32_t>(k.col()) : INT32_MAX;
        if (mc < kc) {
          inner.push_back(mc);
          values.push_back(m.value());
          ++m;
        } else if (kc < mc) {
          inner.push_back(kc);
          values.push_back(h2 * k.value());
          ++k;
        } else {
          // h^2 k rounded before the sum (as it was when the two were
          // summed as separate entries): no fused multiply-add.
          volatile double hk = h2 * k.value();
          inner.push_back(mc);
          values.push_back(m.value() + hk);
          ++m;
          ++k;
        }
      }
      outer[3 * r + a + 1] = static_cast<int32_t>(inner.size());
    }
  }
  SparseMatrix p(3 * n, 3 * n);
  p.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), p.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), p.innerIndexPtr());
  std::copy(values.begin(), values.end(), p.valuePtr());
  std::vector<int32_t>().swap(inner);
  std::vector<double>().swap(values);
  // Fixed DOFs leave the system (their rows of the solve are zero, as
  // Precondition masks them).
  std::vector<uint8_t> fixed_dofs(static_cast<size_t>(3 * n), 0);
  for (int32_t i = 0; i < n; ++i) {
    if (fixed[i]) fixed_dofs[3 * i] = fixed_dofs[3 * i + 1] = fixed_dofs[3 * i + 2] = 1;
  }
  auto flat = std::make_shared<Flat>();
  if (!flat->factor.Factor(p, fixed_dofs, ReducedCholesky::Solves::kSupernodal)) return nullptr;
  return flat;
}

void BackwardEuler::SetStiffnessPreconditioner(const SparseMatrix& k0) {
  std::shared_ptr<Flat> flat = Factor(md_, fixed_, h_, k0);
  if (flat != nullptr) {
    flat_ = std::move(flat);
    return;
  }
  // Keep (or make) the column preconditioner: the factor failed.
  flat_ = nullptr;
  if (!pre_ready_) {
    pre_.Setup(md_, fixed_, Preconditioner::kIncompleteCholesky);
    pre_ready_ = true;
  }
}

void BackwardEuler::Precondition(const Points& r, Points& z) const {
  if (!flat_) {
    pre_.Apply(r, z);
    return;
  }
  // Row-major #control by 3 is the flat DOF vector 3 i + c.
  flat_->factor.SolveVector(r.data(), z.data());  // row-major: DOF 3 i + c
  Mask(z);
}

BackwardEuler::Prepared BackwardEuler::Prepare(const SparseMatrix& mt, const SparseMatrix* dt,
                                               double h, std::vector<uint8_t> fixed,
                                               const SparseMatrix* k0) {
  Prepared p;
  p.h = h;
  p.md = mt;
  if (dt != nullptr) p.md += h * (*dt);
  const int64_t n = mt.rows();
  p.fixed = fixed.empty() ? std::vector<uint8_t>(n, 0) : std::move(fixed);
  // The column preconditioner only where there is no stiffness factor (it
  // is not used beside one; making it took a tenth of a 16^3 block's build).
  if (k0 != nullptr) p.flat = Factor(p.md, p.fixed, h, *k0);
  if (p.flat == nullptr) {
    p.pre.Setup(p.md, p.fixed, Preconditioner::kIncompleteCholesky);
    p.pre_ready = true;
  }
  return p;
}

void BackwardEuler::Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h,
                          std::vector<uint8_t> fixed) {
  Setup(mt, dt, Prepare(*mt, dt, h, std::move(fixed), nullptr));
}

void BackwardEuler::Setup(const SparseMatrix* mt, const SparseMatrix* dt, Prepared prepared) {
  mt_ = mt;
  dt_ = dt;
  h_ = prepared.h;
  md_ = std::move(prepared.md);
  fixed_ = std::move(prepared.fixed);
  pre_ = std::move(prepared.pre);
  pre_ready_ = prepared.pre_ready;
  flat_ = std::move(prepared.flat);
  const int64_t n = mt->rows();
  for (Points* m : {&v_, &rhs_, &x_, &r_, &z_, &p_, &q_, &tmp_, &kx_, &c_}) m->setZero(n, 3);
  ResetWarmStart();
}

void BackwardEuler::ResetWarmStart() {
  const int64_t n = md_.rows();
  history_.last.setZero(n, 3);
  history_.before.setZero(n, 3);
  history_.steps = 0;
}

void BackwardEuler::set_history(History h) {
  assert(h.last.rows() == md_.rows() && h.before.rows() == md_.rows());
  assert(h.steps >= 0 && h.steps <= 2);
  Mask(h.last);
  Mask(h.before);
  history_ = std::move(h);
}

void BackwardEuler::WarmStart() {
  switch (history_.steps) {
    case 0: x_.setZero(); break;
    case 1: x_ = history_.last; break;
    default: x_ = 2.0 * history_.last - history_.before; break;
  }
}

void BackwardEuler::Mask(Points& m) const {
  for (int64_t i = 0; i < m.rows(); ++i) {
    if (fixed_[i]) m.row(i).setZero();
  }
}

void BackwardEuler::Apply(const StiffnessOperator& kt, const Points& x, Points& y) {
  kt(x, tmp_);
  y.noalias() = md_ * x;
  y += (h_ * h_) * tmp_;
  Mask(y);
}

CgStats BackwardEuler::Step(const Points& p, const Points& p_prev, const Points& force,
                            const StiffnessOperator& kt, Points& p_next, double tolerance,
                            int max_iterations) {
  // F - h Kt w from F and one Kt product.
  const ForceAhead from_force = [&](const Points& w, Points& out) {
    kt(w, out);
    out = force - h_ * out;
  };
  return Step(p, p_prev, from_force, kt, p_next, tolerance, max_iterations);
}

CgStats BackwardEuler::Step(const Points& p, const Points& p_prev, const ForceAhead& force_ahead,
                            const StiffnessOperator& kt, Points& p_next, double tolerance,
                            int max_iterations) {
  v_ = (p - p_prev) / h_;
  Mask(v_);
  WarmStart();
  // rhs = h (F - h Kt (v + dv0) - Dt v) (Solve subtracts the Dt term) in one
  // evaluation of the force ahead.
  z_ = v_ + x_;
  force_ahead(z_, tmp_);
  rhs_ = h_ * tmp_;
  return Solve(p, kt, p_next, tolerance, max_iterations);
}

CgStats BackwardEuler::Solve(const Points& p, const StiffnessOperator& kt, Points& p_next,
                             double tolerance, int max_iterations) {
  CgStats stats;
  if (dt_ != nullptr) {
    z_.noalias() = (*dt_) * v_;
    rhs_ -= h_ * z_;
  }
  Mask(rhs_);
  r_ = rhs_;
  r_.noalias() -= md_ * x_;
  Mask(r_);
  double rr = r_.squaredNorm();
  // The stopping test's scale (see the header).
  double bnorm = std::sqrt(rhs_.squaredNorm());
  c_.setZero();
  kx_.setZero();
  if (rr > kTrustedStart * kTrustedStart * bnorm * bnorm && !x_.isZero(0)) {
    // A poor warm start (an abrupt change): b = r0 + S dv0 exactly, one
    // element pass, and the better of dv0 and zero to start from.
    ++rechecked_starts_;
    Apply(kt, x_, q_);  // S dv0; Kt dv0 in tmp_
    z_ = r_ + q_;
    const double bb = z_.squaredNorm();
    if (rr >= bb) {  // zero is the better start: c = dv - dv0 from -dv0
      c_ = -x_;
      kx_ = -tmp_;
      r_ = z_;  // x_ + c_ is zero
      rr = bb;
    }
    bnorm = std::sqrt(bb);
  }
  if (bnorm == 0) bnorm = std::sqrt(rr);  // measured against itself
  int it = 0;
  if (rr > tolerance * tolerance * bnorm * bnorm) {
    Precondition(r_, z_);
    p_ = z_;
    double rz = (r_.array() * z_.array()).sum();
    for (; it < max_iterations; ++it) {
      Apply(kt, p_, q_);
      const double pq = (p_.array() * q_.array()).sum();
      if (pq <= 0) break;
      const double alpha = rz / pq;
      c_ += alpha * p_;
      kx_ += alpha * tmp_;  // Apply left Kt p_ in tmp_
      r_ -= alpha * q_;
      rr = r_.squaredNorm();
      if (std::sqrt(rr) <= tolerance * bnorm) {
        ++it;
        break;
      }
      Precondition(r_, z_);
      const double rz_new = (r_.array() * z_.array()).sum();
      p_ = z_ + (rz_new / rz) * p_;
      rz = rz_new;
    }
  }
  x_ += c_;
  stats.iterations = it;
  stats.max_iterations = it;
  stats.relative_residual = bnorm > 0 ? std::sqrt(rr) / bnorm : 0.0;
  stats.converged = stats.relative_residual <= tolerance;
  history_.before.swap(history_.last);
  history_.last = x_;
  history_.steps = std::min(history_.steps + 1, 2);
  // v' = v + dv, p' = p + h v'.
  p_next = p + h_ * (v_ + x_);
  for (int64_t i = 0; i < p.rows(); ++i) {
    if (fixed_[i]) p_next.row(i) = p.row(i);
  }
  return stats;
}

}  // namespace dynsolid::integrators
