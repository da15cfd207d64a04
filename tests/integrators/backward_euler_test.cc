// Backward Euler's warm-started CG against a dense reference: a stiff linear
// system (rest stiffness K with eigenvalues from 1e2 to 1e8, h^2 K up to 1e4
// times the mass), fixed rows, damping, a load that turns smoothly and then
// jumps. Checks, per step: the TRUE residual ||b - S dv|| against the
// tolerance times ||b|| (the stopping test measures a proxy; see
// backward_euler.h), the folded path (force evaluated ahead) against the
// reference path (F, then Kt products) to rounding with the same iteration
// counts, fewer iterations than cold starts under smooth loads, the poor
// start after the jump rechecked, and the warm-start history as state.
#include "solver/integrators/backward_euler.h"

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

namespace dynsolid::integrators {
namespace {

constexpr int kN = 24;  // control points
constexpr double kH = 1e-2;

struct System {
  SparseMatrix mt, dt;
  Eigen::MatrixXd k;  // 3 kN square, DOFs 3 i + c
  // The preconditioner's stiffness: K with its eigenvalues off by up to 40 %
  // (as the rest stiffness is off from the rotated one): a few iterations.
  SparseMatrix k0;
  std::vector<uint8_t> fixed;
  Points rest;

  System() {
    std::vector<Eigen::Triplet<double, int32_t>> t;
    for (int i = 0; i < kN; ++i) {
      t.emplace_back(i, i, 2.0 + i % 3);
      if (i + 1 < kN) {
        t.emplace_back(i, i + 1, 0.4);
        t.emplace_back(i + 1, i, 0.4);
      }
    }
    mt.resize(kN, kN);
    mt.setFromTriplets(t.begin(), t.end());
    dt = 0.05 * mt;
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    Eigen::MatrixXd a(3 * kN, 3 * kN);
    for (int i = 0; i < a.size(); ++i) a.data()[i] = u(rng);
    const Eigen::MatrixXd q = Eigen::HouseholderQR<Eigen::MatrixXd>(a).householderQ();
    Eigen::VectorXd lambda(3 * kN);
    for (int i = 0; i < 3 * kN; ++i) lambda[i] = std::pow(10.0, 2.0 + 6.0 * i / (3 * kN - 1));
    k = q * lambda.asDiagonal() * q.transpose();
    k = 0.5 * (k + k.transpose()).eval();
    Eigen::VectorXd off(3 * kN);
    for (int i = 0; i < 3 * kN; ++i) off[i] = lambda[i] * (1.0 + 0.4 * u(rng));
    k0 = Eigen::MatrixXd(q * off.asDiagonal() * q.transpose()).sparseView();
    fixed.assign(kN, 0);
    fixed[0] = fixed[5] = 1;
    rest.setZero(kN, 3);
    for (int i = 0; i < kN; ++i) rest.row(i) << i, 0.5 * (i % 4), 0.25 * (i % 3);
  }

  Points Times(const Points& x) const {
    Points out(kN, 3);
    Eigen::Map<Eigen::VectorXd>(out.data(), 3 * kN) =
        k * Eigen::Map<const Eigen::VectorXd>(x.data(), 3 * kN);
    return out;
  }
  // The load at step i: turning smoothly, reversed and tripled from step 40.
  Points Load(int i) const {
    Points f(kN, 3);
    const double a = 0.05 * i, s = i >= 40 ? -3.0 : 1.0;
    for (int j = 0; j < kN; ++j) {
      f.row(j) << s * 1e3 * std::cos(a + 0.1 * j), s * 1e3 * std::sin(a), s * 200.0 * (j % 5);
    }
    return f;
  }
  // Exact b and S (fixed rows and columns replaced by the identity, b's
  // fixed rows zero) at (p, v).
  void Exact(const Points& p, const Points& v, const Points& f, Eigen::VectorXd& b,
             Eigen::MatrixXd& s) const {
    const Points force = f - Times(p - rest);
    Points rhs = kH * (force - kH * Times(v)) - kH * (dt * v);
    b = Eigen::Map<const Eigen::VectorXd>(rhs.data(), 3 * kN);
    s = kH * kH * k;
    const Eigen::MatrixXd md = Eigen::MatrixXd(mt) + kH * Eigen::MatrixXd(dt);
    for (int i = 0; i < kN; ++i) {
      for (int j = 0; j < kN; ++j) {
        for (int c = 0; c < 3; ++c) s(3 * i + c, 3 * j + c) += md(i, j);
      }
    }
    for (int i = 0; i < kN; ++i) {
      if (!fixed[i]) continue;
      for (int c = 0; c < 3; ++c) {
        b[3 * i + c] = 0;
        s.row(3 * i + c).setZero();
        s.col(3 * i + c).setZero();
        s(3 * i + c, 3 * i + c) = 1;
      }
    }
  }
};

struct Trace {
  std::vector<Points> p;
  std::vector<int> iterations;
  std::vector<double> true_residual;  // ||b - S dv|| / ||b||
  std::vector<int64_t> rechecked;     // per step: 1 when the warm start was rechecked
  int64_t rechecks = 0;
};

void Prepare(const System& sys, BackwardEuler& be) {
  be.Setup(&sys.mt, &sys.dt, kH, sys.fixed);
  be.SetStiffnessPreconditioner(sys.k0);
}

enum class Path { kFolded, kReference, kCold };

Trace Simulate(const System& sys, Path path, double tolerance, int steps,
             BackwardEuler* keep = nullptr, int from = 0, Points p0 = {}, Points p_prev0 = {}) {
  BackwardEuler local;
  BackwardEuler& be = keep != nullptr ? *keep : local;
  if (keep == nullptr) Prepare(sys, be);
  Points p = p0.size() ? p0 : sys.rest, p_prev = p_prev0.size() ? p_prev0 : sys.rest, next;
  const BackwardEuler::StiffnessOperator kt = [&](const Points& x, Points& out) {
    out = sys.Times(x);
  };
  Trace r;
  for (int i = from; i < from + steps; ++i) {
    const Points f = sys.Load(i);
    if (path == Path::kCold) be.ResetWarmStart();
    CgStats st;
    const int64_t rechecks_before = be.rechecked_starts();
    if (path == Path::kReference) {
      st = be.Step(p, p_prev, Points(f - sys.Times(p - sys.rest)), kt, next, tolerance, 100);
    } else {
      const BackwardEuler::ForceAhead ahead = [&](const Points& w, Points& out) {
        out = f - sys.Times(p + kH * w - sys.rest);
      };
      st = be.Step(p, p_prev, ahead, kt, next, tolerance, 100);
    }
    EXPECT_TRUE(st.converged) << "step " << i;
    Eigen::VectorXd b;
    Eigen::MatrixXd s;
    Points v = (p - p_prev) / kH;
    for (int j = 0; j < kN; ++j) {
      if (sys.fixed[j]) v.row(j).setZero();
    }
    sys.Exact(p, v, f, b, s);
    const Points dv = be.last_dv();
    const Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(dv.data(), 3 * kN);
    r.true_residual.push_back((b - s * x).norm() / b.norm());
    r.iterations.push_back(st.iterations);
    r.rechecked.push_back(be.rechecked_starts() - rechecks_before);
    p_prev = p;
    p = next;
    r.p.push_back(p);
  }
  r.rechecks = be.rechecked_starts();
  return r;
}

TEST(BackwardEulerTest, WarmStartMeetsTheToleranceOnTheTrueResidual) {
  const System sys;
  for (double tol : {1e-4, 1e-8}) {
    const Trace warm = Simulate(sys, Path::kFolded, tol, 60);
    const Trace cold = Simulate(sys, Path::kCold, tol, 60);
    double worst = 0;
    int warm_its = 0, cold_its = 0, smooth_rechecks = 0;
    for (int i = 0; i < 60; ++i) {
      worst = std::max(worst, warm.true_residual[i]);
      EXPECT_LE(cold.true_residual[i], tol * (1 + 1e-6)) << "cold start, step " << i;
      if (i >= 3 && i < 40) {
        warm_its += warm.iterations[i];
        cold_its += cold.iterations[i];
        smooth_rechecks += warm.rechecked[i];
      }
    }
    std::printf("tolerance %g: worst true residual %.2e of ||b|| (warm); CG iterations over "
                "steps 3-39: %d warm, %d cold; warm starts rechecked: %d of steps 3-39, %lld in all\n",
                tol, worst, warm_its, cold_its, smooth_rechecks,
                static_cast<long long>(warm.rechecks));
    // The proxy scale is within 1 / (1 - kTrustedStart) of ||b|| at worst.
    EXPECT_LE(worst, tol / (1 - BackwardEuler::kTrustedStart)) << "tolerance " << tol;
    EXPECT_LT(warm_its, cold_its) << "warm starts save iterations under a smooth load";
    // The jump at step 40 leaves a poor start: rechecked, not trusted.
    EXPECT_EQ(warm.rechecked[40], 1);
    EXPECT_EQ(cold.rechecks, 0) << "a cold start has nothing to recheck";
  }
}

TEST(BackwardEulerTest, FoldedAndReferencePathsAgree) {
  const System sys;
  const Trace a = Simulate(sys, Path::kFolded, 1e-6, 60);
  const Trace b = Simulate(sys, Path::kReference, 1e-6, 60);
  double dev = 0, disp = 0;
  for (int i = 0; i < 60; ++i) {
    EXPECT_EQ(a.iterations[i], b.iterations[i]) << "step " << i;
    dev = std::max(dev, (a.p[i] - b.p[i]).cwiseAbs().maxCoeff());
    disp = std::max(disp, (b.p[i] - sys.rest).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(dev, 1e-10 * disp);
  EXPECT_EQ(a.rechecks, b.rechecks);
}

TEST(BackwardEulerTest, TheWarmStartHistoryIsState) {
  const System sys;
  BackwardEuler first;
  Prepare(sys, first);
  const Trace a = Simulate(sys, Path::kFolded, 1e-4, 20, &first);
  ASSERT_EQ(first.history().steps, 2);
  BackwardEuler copy;
  Prepare(sys, copy);
  EXPECT_EQ(copy.history().steps, 0) << "Setup clears the history";
  copy.set_history(first.history());
  const Points p = a.p[19], p_prev = a.p[18];
  const Trace b = Simulate(sys, Path::kFolded, 1e-4, 10, &first, 20, p, p_prev);
  const Trace c = Simulate(sys, Path::kFolded, 1e-4, 10, &copy, 20, p, p_prev);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(b.p[i], c.p[i]) << "step " << 20 + i;
  // Without the history the same steps take other iterates.
  BackwardEuler fresh;
  Prepare(sys, fresh);
  const Trace d = Simulate(sys, Path::kFolded, 1e-4, 1, &fresh, 20, p, p_prev);
  EXPECT_NE(d.p[0], b.p[0]);
}

}  // namespace
}  // namespace dynsolid::integrators
