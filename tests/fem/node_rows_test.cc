#include "solver/fem/node_rows.h"

#include <random>

#include <gtest/gtest.h>

#include "solver/subdivision/mcj.h"
#include "tests/testing/meshes.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::fem {
namespace {

using Sparse = Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>;

Points RandomPoints(int64_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  Points p(n, 3);
  for (int64_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) p(i, c) = u(rng);
  return p;
}

// `levels` of subdivision; with `crease_degrees` > 0 the boundary edges
// sharper than that are tagged sharp.
Sparse Refined(const mesh::MeshInput& in, int levels, double crease_degrees = 0) {
  auto m = mesh::CellComplex::FromInput(in);
  EXPECT_OK(m);
  std::vector<uint8_t> sharp;
  if (crease_degrees > 0) {
    sharp.assign(m->num_edges(), 0);
    subdivision::TagCreases(*m, crease_degrees, sharp);
  }
  auto h = subdivision::Subdivide(std::make_shared<const mesh::CellComplex>(*std::move(m)),
                                  levels, std::move(sharp));
  EXPECT_OK(h);
  return h->a;
}

// Products against Eigen's on the same matrix; Row against Multiply's row.
void ExpectProductsMatch(const Sparse& a) {
  const NodeRows rows(a);
  ASSERT_EQ(rows.rows(), a.rows());
  ASSERT_EQ(rows.cols(), a.cols());
  const Points p = RandomPoints(a.cols(), 1), g = RandomPoints(a.rows(), 2);
  const Points want = a * p;
  const Points got = rows.Multiply(p);
  EXPECT_LE((got - want).cwiseAbs().maxCoeff(), 1e-13 * want.cwiseAbs().maxCoeff());
  for (int64_t i : {int64_t{0}, a.rows() / 2, a.rows() - 1}) {
    const Eigen::Vector3d row = rows.Row(p, i);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(row(c), got(i, c)) << "row " << i;
  }
  // In two ranges, summed: A^T g.
  const Points want_t = a.transpose() * g;
  Points first, second;
  rows.MultiplyTransposed(g, 0, a.rows() / 3, first);
  rows.MultiplyTransposed(g, a.rows() / 3, a.rows(), second);
  const Points got_t = first + second;
  EXPECT_LE((got_t - want_t).cwiseAbs().maxCoeff(), 1e-13 * want_t.cwiseAbs().maxCoeff());
}

TEST(NodeRowsTest, BlockWithSharpEdgesStoresFloatValuesAndShortColumns) {
  // Two levels of a block with its box edges sharp (the Table-1 blocks):
  // every weight a dyadic fraction.
  const Sparse a = Refined(testing::Grid(3, 3, 3), 2, 60);
  const NodeRows rows(a);
  EXPECT_TRUE(rows.float_values());
  EXPECT_TRUE(rows.short_columns());
  // 2 bytes of column and 4 of value per entry, plus the row starts.
  EXPECT_EQ(rows.bytes(), 6 * a.nonZeros() + 8 * (a.rows() + 1));
  ExpectProductsMatch(a);
}

TEST(NodeRowsTest, WeightsThatAreNotFloatsStayDouble) {
  // A block with smooth boundary: its corners are valence-3 surface
  // vertices, whose rules weigh by thirds.
  const Sparse a = Refined(testing::Grid(2, 2, 2), 2);
  bool inexact = false;
  for (int64_t k = 0; k < a.nonZeros(); ++k) {
    const double v = a.valuePtr()[k];
    inexact |= static_cast<double>(static_cast<float>(v)) != v;
  }
  ASSERT_TRUE(inexact) << "the test needs a weight that is not a float";
  const NodeRows rows(a);
  EXPECT_FALSE(rows.float_values());
  EXPECT_EQ(rows.bytes(), 10 * a.nonZeros() + 8 * (a.rows() + 1));
  ExpectProductsMatch(a);
}

TEST(NodeRowsTest, ManyColumnsTakeWideIndices) {
  // 70000 columns: indices above 65535 need 32 bits.
  const int64_t cols = 70000;
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (int32_t i = 0; i < 500; ++i) {
    t.emplace_back(i, (i * 137) % cols, 0.25);
    t.emplace_back(i, cols - 1 - i, 0.75);
  }
  Sparse a(500, cols);
  a.setFromTriplets(t.begin(), t.end());
  const NodeRows rows(a);
  EXPECT_FALSE(rows.short_columns());
  EXPECT_TRUE(rows.float_values());
  ExpectProductsMatch(a);
}

}  // namespace
}  // namespace dynsolid::fem
