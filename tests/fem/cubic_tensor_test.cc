// The cubic element's sum-factorized products against the dense tables.
#include "solver/fem/cubic_tensor.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

namespace dynsolid::fem {
namespace {

TEST(CubicTensorProductsTest, EqualTheDenseTablesTimesTheNodeValues) {
  const KindTable table = MakeKindTable(ElementKind::kCubic);
  ASSERT_TRUE(CubicTensorProducts::Applies(table));
  EXPECT_FALSE(CubicTensorProducts::Applies(MakeKindTable(ElementKind::kLinear)));
  EXPECT_FALSE(CubicTensorProducts::Applies(MakeKindTable(ElementKind::kCubic, 3)));
  const CubicTensorProducts products(table);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  const int cols = 7, ld = 70;  // a leading dimension above 64 on both sides
  Eigen::MatrixXd x(ld, cols);
  for (int c = 0; c < cols; ++c)
    for (int r = 0; r < ld; ++r) x(r, c) = u(rng);
  Eigen::MatrixXd values = Eigen::MatrixXd::Zero(ld, cols);
  std::array<Eigen::MatrixXd, 3> d;
  for (auto& m : d) m = Eigen::MatrixXd::Zero(ld, cols);
  products.Values(x.data(), ld, cols, values.data(), ld);
  products.Derivatives(x.data(), ld, cols, d[0].data(), d[1].data(), d[2].data(), ld);
  double largest = 0, worst = 0;
  for (int c = 0; c < cols; ++c) {
    for (int q = 0; q < 64; ++q) {
      double n = 0;
      double g[3] = {0, 0, 0};
      for (int m = 0; m < 64; ++m) {
        n += table.N(q)[m] * x(m, c);
        for (int k = 0; k < 3; ++k) g[k] += table.dN(q)[3 * m + k] * x(m, c);
      }
      largest = std::max({largest, std::abs(n), std::abs(g[0]), std::abs(g[1]), std::abs(g[2])});
      worst = std::max(worst, std::abs(values(q, c) - n));
      for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(d[k](q, c) - g[k]));
    }
    // Rows past the 64 points are left alone.
    for (int r = 64; r < ld; ++r) {
      EXPECT_EQ(values(r, c), 0);
      for (const auto& m : d) EXPECT_EQ(m(r, c), 0);
    }
  }
  EXPECT_GT(largest, 0.1);
  EXPECT_LT(worst, 1e-14 * 64 * largest) << "largest " << largest;
  // The values made beside the derivatives are Values' to the bit.
  Eigen::MatrixXd beside = Eigen::MatrixXd::Zero(ld, cols);
  products.Derivatives(x.data(), ld, cols, d[0].data(), d[1].data(), d[2].data(), ld,
                       beside.data());
  EXPECT_EQ(beside, values);
}

// The rest Jacobians from the derivatives equal RestJacobians' (dense,
// node by node) up to rounding, on a curved element (a cube's nodes moved
// by a smooth map).
TEST(CubicTensorProductsTest, JacobiansEqualTheDenseRestJacobians) {
  const KindTable table = MakeKindTable(ElementKind::kCubic);
  const CubicTensorProducts products(table);
  NodeMatrixX3 x(64, 3);
  for (int m = 0; m < 64; ++m) {
    const double u = m / 16, v = (m / 4) % 4, w = m % 4;
    x.row(m) << u + 0.1 * std::sin(v), v + 0.05 * u * w, 0.8 * w + 0.02 * u * u;
  }
  std::vector<double> dense, factorized;
  RestJacobians(table, x, dense);
  products.Jacobians(x, factorized);
  ASSERT_EQ(dense.size(), factorized.size());
  double largest = 0, worst = 0;
  for (size_t i = 0; i < dense.size(); ++i) {
    largest = std::max(largest, std::abs(dense[i]));
    worst = std::max(worst, std::abs(dense[i] - factorized[i]));
  }
  EXPECT_GT(largest, 0.5);
  EXPECT_LT(worst, 1e-13 * largest);
}

}  // namespace
}  // namespace dynsolid::fem
