// The rest Jacobians of an element, all points at once, against the
// per-point form and against an affine element's exact Jacobian.
#include "solver/fem/element_data.h"

#include <random>

#include <Eigen/Dense>
#include <gtest/gtest.h>

namespace dynsolid::fem {
namespace {

// Rest nodes of `kind`'s element whose map is x(u) = A u: the nodes that
// fit it at the quadrature points in least squares (exact for kinds that
// reproduce linear functions), then each moved by up to `jitter` at random.
NodeMatrixX3 Nodes(const KindTable& table, const Eigen::Matrix3d& a, double jitter, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  NodeMatrixX3 x(table.nodes, 3);
  Eigen::MatrixXd nq(table.points, table.nodes);
  Eigen::MatrixXd uq(table.points, 3);
  for (int q = 0; q < table.points; ++q) {
    for (int i = 0; i < table.nodes; ++i) nq(q, i) = table.N(q)[i];
    uq.row(q) = (a * table.uvw[q]).transpose();
  }
  const Eigen::MatrixXd fit = nq.completeOrthogonalDecomposition().solve(uq);
  for (int i = 0; i < table.nodes; ++i) {
    for (int c = 0; c < 3; ++c) x(i, c) = fit(i, c) + u(rng);
  }
  return x;
}

TEST(RestJacobiansTest, EqualThePerPointJacobiansToTheBit) {
  for (ElementKind kind : {ElementKind::kCubic, ElementKind::kLinear, ElementKind::kPyramid}) {
    const KindTable table = MakeKindTable(kind);
    Eigen::Matrix3d a;
    a << 1.0, 0.2, 0.0, -0.1, 0.9, 0.3, 0.05, 0.0, 1.1;
    const NodeMatrixX3 x = Nodes(table, a, 0.05, 7 + static_cast<uint32_t>(kind));
    std::vector<double> j;
    RestJacobians(table, x, j);
    ASSERT_EQ(j.size(), 9u * table.points);
    for (int q = 0; q < table.points; ++q) {
      const Eigen::Matrix3d one = RestJacobian(table.dN(q), x, table.nodes);
      const Eigen::Matrix3d all = JacobianAt(j, table.points, q);
      for (int e = 0; e < 9; ++e) {
        EXPECT_EQ(all(e / 3, e % 3), one(e / 3, e % 3))
            << "kind " << static_cast<int>(kind) << " point " << q << " entry " << e;
      }
      EXPECT_EQ(JacobianDeterminant(table.dN(q), x, table.nodes), one.determinant());
    }
  }
}

TEST(RestJacobiansTest, AnAffineElementHasItsMapsJacobianAtEveryPoint) {
  for (ElementKind kind : {ElementKind::kCubic, ElementKind::kLinear}) {
    const KindTable table = MakeKindTable(kind);
    Eigen::Matrix3d a;
    a << 2.0, 0.5, 0.0, 0.0, 1.5, -0.25, 0.1, 0.0, 0.75;
    const NodeMatrixX3 x = Nodes(table, a, 0.0, 1);
    std::vector<double> j;
    RestJacobians(table, x, j);
    for (int q = 0; q < table.points; ++q) {
      EXPECT_LT((JacobianAt(j, table.points, q) - a).cwiseAbs().maxCoeff(), 1e-12)
          << "kind " << static_cast<int>(kind) << " point " << q;
    }
  }
}

}  // namespace
}  // namespace dynsolid::fem
