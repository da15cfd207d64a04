#include "solver/fem/element_data.h"

#include <cmath>

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
  t.dn_by_node.resize(t.dn.size());
  for (int q = 0; q < t.points; ++q) {
    for (int e = 0; e < 3 * t.nodes; ++e) {
      t.dn_by_node[static_cast<size_t>(e) * t.points + q] = t.dn[static_cast<size_t>(q) * t.nodes * 3 + e];
    }
  }
  t.centre_n.resize(t.nodes);
  t.centre_dn.resize(t.nodes * 3);
  Shape(kind, 0.5, 0.5, 0.5, t.centre_n.data(), t.centre_dn.data());
  return t;
}

Eigen::Matrix3d RestJacobian(const double* dn, const NodeMatrixX3& x, int nodes) {
  // Nine sums, each in node order, over contiguous rows (x is n x 3 row
  // major, dn n x 3): Eigen's outer product per node, or a dynamic-size
  // product that goes through its general matrix product for a 3 x 3
  // result, took most of a build of many distinct shapes.
  const double* xp = x.data();
  double j00 = 0, j01 = 0, j02 = 0, j10 = 0, j11 = 0, j12 = 0, j20 = 0, j21 = 0, j22 = 0;
  for (int i = 0; i < nodes; ++i) {
    const double x0 = xp[3 * i], x1 = xp[3 * i + 1], x2 = xp[3 * i + 2];
    const double d0 = dn[3 * i], d1 = dn[3 * i + 1], d2 = dn[3 * i + 2];
    // Fused multiply-adds, explicitly: RestJacobians' vector loop makes the
    // same ones.
    j00 = std::fma(x0, d0, j00);
    j01 = std::fma(x0, d1, j01);
    j02 = std::fma(x0, d2, j02);
    j10 = std::fma(x1, d0, j10);
    j11 = std::fma(x1, d1, j11);
    j12 = std::fma(x1, d2, j12);
    j20 = std::fma(x2, d0, j20);
    j21 = std::fma(x2, d1, j21);
    j22 = std::fma(x2, d2, j22);
  }
  Eigen::Matrix3d j;
  j << j00, j01, j02, j10, j11, j12, j20, j21, j22;
  return j;
}

void RestJacobians(const KindTable& table, const NodeMatrixX3& x, std::vector<double>& j) {
  const int n = table.nodes, points = table.points;
  j.resize(static_cast<size_t>(9) * points);
  const double* xp = x.data();
  constexpr int kLanes = 4;
  int q0 = 0;
  for (; q0 + kLanes <= points; q0 += kLanes) {
    // Nine sums per point, each in node order (as RestJacobian): nine
    // vectors of four points.
    double acc[9][kLanes] = {};
    for (int i = 0; i < n; ++i) {
      const double* d = table.dn_by_node.data() + static_cast<size_t>(3 * i) * points + q0;
      for (int r = 0; r < 3; ++r) {
        const double xr = xp[3 * i + r];
        for (int c = 0; c < 3; ++c) {
          for (int k = 0; k < kLanes; ++k) {
            acc[3 * r + c][k] = std::fma(xr, d[c * points + k], acc[3 * r + c][k]);
          }
        }
      }
    }
    for (int e = 0; e < 9; ++e) {
      for (int k = 0; k < kLanes; ++k) j[static_cast<size_t>(e) * points + q0 + k] = acc[e][k];
    }
  }
  for (; q0 < points; ++q0) {
    const Eigen::Matrix3d one = RestJacobian(table.dN(q0), x, n);
    for (int e = 0; e < 9; ++e) j[static_cast<size_t>(e) * points + q0] = one(e / 3, e % 3);
  }
}

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
