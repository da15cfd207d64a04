#include "solver/models/panel_product.h"

#include <cmath>

#include <gtest/gtest.h>

#include "tests/models/random_matrix.h"

namespace dynsolid::models {
namespace {

// Every shape the models use (local-frame n x n for n = 64, 8, 5;
// corotational 3n x 3n) and batch sizes around the 6-column micro-kernel.
TEST(PackedMatrixTest, MatchesEigenProductForEveryShapeAndBatchSize) {
  for (int n : {5, 8, 15, 24, 64, 192}) {
    const Eigen::MatrixXd k = RandomMatrix(n, n, 7u + n);
    const PackedMatrix packed(k);
    ASSERT_EQ(packed.rows(), n);
    ASSERT_EQ(packed.padded_rows() % PackedMatrix::kPanel, 0);
    ASSERT_GE(packed.padded_rows(), n);
    for (int count : {1, 2, 5, 6, 7, 12, 13, 64}) {
      const int ld = packed.padded_rows() + 3;  // strides larger than the rows
      Eigen::MatrixXd x = RandomMatrix(ld, count, 11u + count);
      Eigen::MatrixXd y = Eigen::MatrixXd::Constant(ld, count, 99.0);
      packed.Apply(x.data(), ld, count, y.data(), ld);
      const Eigen::MatrixXd want = k * x.topRows(n);
      for (int j = 0; j < count; ++j) {
        for (int i = 0; i < n; ++i) {
          EXPECT_NEAR(y(i, j), want(i, j), 1e-13 * n) << "n " << n << " count " << count;
        }
        for (int i = n; i < packed.padded_rows(); ++i) EXPECT_EQ(y(i, j), 0.0);
        for (int i = packed.padded_rows(); i < ld; ++i) EXPECT_EQ(y(i, j), 99.0);
      }
    }
  }
}

// A column's result has the same bits wherever it sits in a batch and
// whatever the batch size: each entry is one fma chain in a fixed order.
TEST(PackedMatrixTest, ColumnBitsDoNotDependOnTheBatch) {
  const int n = 64;
  const PackedMatrix packed(RandomMatrix(n, n, 3));
  const Eigen::MatrixXd x = RandomMatrix(n, 17, 5);
  Eigen::MatrixXd all(n, 17);
  packed.Apply(x.data(), n, 17, all.data(), n);
  for (int j = 0; j < 17; ++j) {
    Eigen::VectorXd one(n);
    packed.Apply(x.col(j).data(), n, 1, one.data(), n);
    for (int i = 0; i < n; ++i) ASSERT_EQ(one(i), all(i, j)) << "row " << i << " column " << j;
  }
}

// Each entry equals the fma chain over k in ascending order (the
// documented rounding, shared by the SIMD and the portable paths).
TEST(PackedMatrixTest, EntriesAreAscendingFmaChains) {
  const int n = 24;
  const Eigen::MatrixXd k = RandomMatrix(n, n, 9), x = RandomMatrix(n, 3, 10);
  const PackedMatrix packed(k);
  Eigen::MatrixXd y(packed.padded_rows(), 3);
  packed.Apply(x.data(), n, 3, y.data(), packed.padded_rows());
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < n; ++i) {
      double acc = 0;
      for (int c = 0; c < n; ++c) acc = std::fma(k(i, c), x(c, j), acc);
      ASSERT_EQ(y(i, j), acc);
    }
  }
}

// The single-precision copy: every shape and batch size against the double
// product, to float rounding of the sum of |K| |x| terms; padding rows zero.
TEST(PackedMatrixFTest, MatchesTheDoubleProductToFloatRounding) {
  for (int n : {5, 8, 15, 24, 45, 192}) {
    const Eigen::MatrixXd k = RandomMatrix(n, n, 17u + n);
    const PackedMatrixF packed{PackedMatrix(k)};
    ASSERT_EQ(packed.padded_rows() % PackedMatrixF::kPanel, 0);
    ASSERT_GE(packed.padded_rows(), n);
    for (int count : {1, 5, 6, 7, 13, 64}) {
      const int ld = packed.padded_rows() + 3;
      const Eigen::MatrixXd x = RandomMatrix(ld, count, 21u + count);
      const Eigen::MatrixXf xf = x.cast<float>();
      Eigen::MatrixXd y = Eigen::MatrixXd::Constant(ld, count, 99.0);
      packed.Apply(xf.data(), ld, count, y.data(), ld);
      const Eigen::MatrixXd want = k * x.topRows(n);
      const Eigen::MatrixXd scale = k.cwiseAbs() * x.topRows(n).cwiseAbs();
      for (int j = 0; j < count; ++j) {
        for (int i = 0; i < n; ++i) {
          EXPECT_NEAR(y(i, j), want(i, j), 4 * n * 6e-8 * scale(i, j)) << "n " << n;
        }
        for (int i = n; i < packed.padded_rows(); ++i) EXPECT_EQ(y(i, j), 0.0);
        for (int i = packed.padded_rows(); i < ld; ++i) EXPECT_EQ(y(i, j), 99.0);
      }
    }
  }
}

// Float fma chains over k in ascending order, widened to double: the same
// bits wherever a column sits in a batch.
TEST(PackedMatrixFTest, EntriesAreAscendingFloatFmaChains) {
  const int n = 24;
  const Eigen::MatrixXd k = RandomMatrix(n, n, 9);
  const Eigen::MatrixXf x = RandomMatrix(n, 7, 10).cast<float>();
  const PackedMatrixF packed{PackedMatrix(k)};
  const Eigen::MatrixXf kf = k.cast<float>();
  Eigen::MatrixXd y(packed.padded_rows(), 7);
  packed.Apply(x.data(), n, 7, y.data(), packed.padded_rows());
  for (int j = 0; j < 7; ++j) {
    Eigen::VectorXd one(packed.padded_rows());
    packed.Apply(x.col(j).data(), n, 1, one.data(), packed.padded_rows());
    for (int i = 0; i < n; ++i) {
      float acc = 0;
      for (int c = 0; c < n; ++c) acc = std::fma(kf(i, c), x(c, j), acc);
      ASSERT_EQ(y(i, j), static_cast<double>(acc));
      ASSERT_EQ(one(i), y(i, j)) << "row " << i << " column " << j;
    }
  }
}

}  // namespace
}  // namespace dynsolid::models
