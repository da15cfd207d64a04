#include "solver/fem/quadrature.h"

#include <cmath>

#include <gtest/gtest.h>

#include "solver/fem/basis.h"

namespace dynsolid::fem {
namespace {

TEST(QuadratureTest, GaussLegendreIsExactToDegree2nMinus1) {
  for (int n = 1; n <= 8; ++n) {
    const Rule1d r = GaussLegendre(n);
    for (int p = 0; p <= 2 * n - 1; ++p) {
      double s = 0.0;
      for (int i = 0; i < n; ++i) s += r.weights[i] * std::pow(r.points[i], p);
      EXPECT_NEAR(s, 1.0 / (p + 1), 1e-14) << n << "-point rule, integral of t^" << p;
    }
    // and not exact one degree higher (so the test can fail)
    double s = 0.0;
    for (int i = 0; i < n; ++i) s += r.weights[i] * std::pow(r.points[i], 2 * n);
    EXPECT_GT(std::abs(s - 1.0 / (2 * n + 1)), 1e-12) << n << "-point rule at degree 2n";
  }
}

TEST(QuadratureTest, CubeRuleIntegratesTrivariatePolynomial) {
  const Rule3d q = GaussLegendreCube(4);
  ASSERT_EQ(q.points.size(), 64u);
  double s = 0.0, vol = 0.0;
  for (size_t i = 0; i < q.points.size(); ++i) {
    const auto& x = q.points[i];
    s += q.weights[i] * std::pow(x[0], 7) * std::pow(x[1], 3) * x[2] * x[2];
    vol += q.weights[i];
  }
  EXPECT_NEAR(vol, 1.0, 1e-14);
  EXPECT_NEAR(s, 1.0 / 8.0 / 4.0 / 3.0, 1e-14);
}

TEST(BasisTest, CubicBSplinePartitionOfUnityAndDerivative) {
  for (double t = 0.0; t <= 1.0; t += 0.0625) {
    const auto b = CubicBSpline(t);
    const auto db = CubicBSplineDerivative(t);
    EXPECT_NEAR(b[0] + b[1] + b[2] + b[3], 1.0, 1e-15);
    EXPECT_NEAR(db[0] + db[1] + db[2] + db[3], 0.0, 1e-15);
    // Linear precision: sum of B_i (i - 1) reproduces t.
    EXPECT_NEAR(-b[0] + b[2] + 2.0 * b[3], t, 1e-15);
    const double h = 1e-6;
    const auto bp = CubicBSpline(t + h), bm = CubicBSpline(t - h);
    for (int i = 0; i < 4; ++i) {
      EXPECT_NEAR(db[i], (bp[i] - bm[i]) / (2 * h), 1e-8) << "dB_" << i << " at " << t;
    }
  }
}

}  // namespace
}  // namespace dynsolid::fem
