#include "solver/fem/element_data.h"

#include <Eigen/LU>

#include "solver/fem/quadrature.h"

namespace dynsolid::fem {

KindTable MakeKindTable(ElementKind kind, int order) {
  KindTable t;
  t.kind = kind;
  t.nodes = NodesOf(kind);
  const Rule3d rule = GaussLegendreCube(order > 0 ? order : QuadratureOrder(kind));
  t.points = static_cast<int>(rule.points.size());
  t.n.resize(static_cast<size_t>(t.points) * t.nodes);
  t.dn.resize(static_cast<size_t>(t.points) * t.nodes * 3);
  t.weight = rule.weights;
  t.uvw = rule.points;
  for (int q = 0; q < t.points; ++q) {
    const Eigen::Vector3d& p = rule.points[q];
    Shape(kind, p[0], p[1], p[2], t.n.data() + static_cast<size_t>(q) * t.nodes,
          t.dn.data() + static_cast<size_t>(q) * t.nodes * 3);
  }
  t.centre_n.resize(t.nodes);
  t.centre_dn.resize(t.nodes * 3);
  Shape(kind, 0.5, 0.5, 0.5, t.centre_n.data(), t.centre_dn.data());
  return t;
}

namespace {
// J0 = sum_i x_i dN_i^T (3 x 3: rows physical, columns parametric).
Eigen::Matrix3d RestJacobian(const double* dn, const NodeMatrixX3& x, int nodes) {
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  for (int i = 0; i < nodes; ++i) {
    const Eigen::Map<const Eigen::RowVector3d> d(dn + 3 * i);
    j += x.row(i).transpose() * d;
  }
  return j;
}
}  // namespace

double JacobianDeterminant(const double* dn, const NodeMatrixX3& x, int nodes) {
  return RestJacobian(dn, x, nodes).determinant();
}

double PhysicalGradients(const double* dn, const NodeMatrixX3& x, int nodes, NodeMatrixX3& g) {
  const Eigen::Matrix3d j = RestJacobian(dn, x, nodes);
  const double det = j.determinant();
  g.resize(nodes, 3);
  if (det <= 0.0) {
    g.setZero();
    return det;
  }
  const Eigen::Matrix3d jinv = j.inverse();
  // dN/dx = dN/du * du/dx: row i of G = dN_i^T J0^-1.
  for (int i = 0; i < nodes; ++i) {
    const Eigen::Map<const Eigen::RowVector3d> d(dn + 3 * i);
    g.row(i) = d * jinv;
  }
  return det;
}

}  // namespace dynsolid::fem
