// dynsolid::SparseMatrix (solver/common/sparse_matrix.h): Eigen's row-major
// sparse matrix whose moves hand the arrays over instead of copying them.
#include "solver/common/sparse_matrix.h"

#include <utility>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

namespace dynsolid {
namespace {

// 3 x 4, rows 0 and 2 filled.
SparseMatrix Example() {
  std::vector<Eigen::Triplet<double, int32_t>> t = {{0, 0, 1.0}, {0, 3, 2.0}, {2, 1, -3.0}};
  SparseMatrix m(3, 4);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

Eigen::MatrixXd Dense(const SparseMatrix::Base& m) { return Eigen::MatrixXd(m); }

TEST(SparseMatrixTest, MoveConstructionHandsTheArraysOver) {
  SparseMatrix a = Example();
  const Eigen::MatrixXd want = Dense(a);
  const double* values = a.valuePtr();
  const int32_t* inner = a.innerIndexPtr();
  SparseMatrix b(std::move(a));
  EXPECT_EQ(b.valuePtr(), values);  // the same memory: nothing copied
  EXPECT_EQ(b.innerIndexPtr(), inner);
  EXPECT_EQ(Dense(b), want);
  EXPECT_EQ(a.nonZeros(), 0);  // the moved-from matrix is empty
  EXPECT_EQ(a.rows(), 0);
}

TEST(SparseMatrixTest, MoveAssignmentHandsTheArraysOverAndEmptiesTheSource) {
  SparseMatrix a = Example();
  const Eigen::MatrixXd want = Dense(a);
  const double* values = a.valuePtr();
  SparseMatrix b(5, 5);
  b.insert(4, 4) = 7.0;
  b = std::move(a);
  EXPECT_EQ(b.valuePtr(), values);
  EXPECT_EQ(Dense(b), want);
  EXPECT_EQ(a.rows(), 0);
  EXPECT_EQ(a.nonZeros(), 0);
  b = std::move(b);  // self move keeps the matrix
  EXPECT_EQ(Dense(b), want);
}

TEST(SparseMatrixTest, MovesFromEigensOwnType) {
  SparseMatrix::Base plain = Example();
  const double* values = plain.valuePtr();
  SparseMatrix a(std::move(plain));
  EXPECT_EQ(a.valuePtr(), values);
  SparseMatrix::Base other = Example();
  values = other.valuePtr();
  SparseMatrix b;
  b = std::move(other);
  EXPECT_EQ(b.valuePtr(), values);
  EXPECT_EQ(other.nonZeros(), 0);
}

TEST(SparseMatrixTest, CopiesStayCopies) {
  const SparseMatrix a = Example();
  SparseMatrix b(a);
  EXPECT_NE(b.valuePtr(), a.valuePtr());
  EXPECT_EQ(Dense(b), Dense(a));
  SparseMatrix c;
  c = a;
  EXPECT_NE(c.valuePtr(), a.valuePtr());
  EXPECT_EQ(Dense(c), Dense(a));
}

TEST(SparseMatrixTest, TakesEigenExpressions) {
  const SparseMatrix a = Example();
  SparseMatrix product = a * SparseMatrix(a.transpose());  // 3 x 3
  Eigen::MatrixXd want = Dense(a) * Dense(a).transpose();
  EXPECT_TRUE(Dense(product).isApprox(want));
  SparseMatrix t;
  t = a.transpose();
  EXPECT_EQ(Dense(t), Dense(a).transpose());
  Eigen::Matrix<double, Eigen::Dynamic, 3> p = Eigen::Matrix<double, Eigen::Dynamic, 3>::Ones(4, 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3> q = a * p;  // sparse times dense
  EXPECT_DOUBLE_EQ(q(0, 0), 3.0);
  EXPECT_DOUBLE_EQ(q(2, 2), -3.0);
  int entries = 0;
  for (SparseMatrix::InnerIterator it(a, 0); it; ++it) ++entries;
  EXPECT_EQ(entries, 2);
}

}  // namespace
}  // namespace dynsolid
