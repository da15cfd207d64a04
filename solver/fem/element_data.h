// Quadrature tables per element kind and the rest geometry of an element
// at its quadrature points (docs/model.md section 3).
//
// An element matrix is a quadrature loop that reads like the formula:
//   for q: dV = det(J0_q) w_q; G_q = dN_q J0_q^-1; M += mu N_q N_q^T dV ...
#pragma once

#include <vector>

#include <Eigen/Core>

#include "solver/fem/element_set.h"
#include "solver/fem/shape.h"

namespace dynsolid::fem {

// Shape functions of one kind tabulated at its Gauss points.
struct KindTable {
  ElementKind kind = ElementKind::kLinear;
  int nodes = 0;       // n
  int points = 0;      // Q
  // Q x n values, Q x (n x 3) parametric derivatives, Q weights (sum 1),
  // Q parametric points.
  std::vector<double> n;
  std::vector<double> dn;
  std::vector<double> weight;
  std::vector<Eigen::Vector3d> uvw;
  // Values and derivatives at the element centre (0.5, 0.5, 0.5).
  std::vector<double> centre_n, centre_dn;
  // The derivatives again, point-minor: dn_by_node[(3 i + c) Q + q] is
  // dN_i / du_c at point q (RestJacobians' vector loop reads them so).
  std::vector<double> dn_by_node;

  const double* N(int q) const { return n.data() + static_cast<size_t>(q) * nodes; }
  const double* dN(int q) const { return dn.data() + static_cast<size_t>(q) * nodes * 3; }
};

// The table of `kind` with QuadratureOrder(kind) points per direction
// (or `order` when > 0).
KindTable MakeKindTable(ElementKind kind, int order = 0);

using NodeMatrixX3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// Rest geometry of one element at one quadrature point.
struct PointGeometry {
  double dv = 0;              // det(J0) * weight: rest volume, m^3
  double det = 0;             // det(J0)
  Eigen::Vector3d x;          // rest position of the point
};

// The rest Jacobian J0 = sum_i x_i dN_i^T (3 x 3: rows physical, columns
// parametric) at the parametric point with derivatives `dn` (n x 3) for
// rest nodes `x` (n x 3). Every function here forms J0 this way, so their
// determinants agree to the bit.
Eigen::Matrix3d RestJacobian(const double* dn, const NodeMatrixX3& x, int nodes);

// The rest Jacobians of rest nodes `x` at every point of `table`:
// j[(3 r + c) Q + q] = J0_q(r, c), the same bits as RestJacobian(dN(q))
// (each sum in node order), four points at a time.
void RestJacobians(const KindTable& table, const NodeMatrixX3& x, std::vector<double>& j);
// J0_q of RestJacobians' output.
inline Eigen::Matrix3d JacobianAt(const std::vector<double>& j, int points, int q) {
  Eigen::Matrix3d m;
  for (int e = 0; e < 9; ++e) m(e / 3, e % 3) = j[static_cast<size_t>(e) * points + q];
  return m;
}

// Physical gradients G = dN J0^-1 (n x 3, 1/m) of the shape functions at
// parametric point with derivatives `dn` (n x 3) for rest nodes `x` (n x 3).
// Returns det(J0) (m^3 per unit parametric volume; <= 0 for an inverted
// element).
double PhysicalGradients(const double* dn, const NodeMatrixX3& x, int nodes, NodeMatrixX3& g);
// det(J0) alone, the same bits as PhysicalGradients' return value.
double JacobianDeterminant(const double* dn, const NodeMatrixX3& x, int nodes);

}  // namespace dynsolid::fem
