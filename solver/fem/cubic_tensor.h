// Products of a cubic B-spline element's shape functions, and of their
// parametric derivatives, at its 4 x 4 x 4 Gauss points with columns of
// node values, by sum factorization.
//
// The element's shape functions are products of 1D B-spline pieces and its
// rule is the tensor product of a 1D Gauss rule (fem::CubicShape: node
// m = 16 i + 4 j + k has u index i, v index j, w index k; point
// q = 16 a + 4 b + c likewise), so at the points
//   N  = A (x) A (x) A,   dN/du = A' (x) A (x) A,  dN/dv = A (x) A' (x) A,
//   dN/dw = A (x) A (x) A',
// with A(a, i) the i-th piece at the a-th 1D point and A' its derivative.
// A product with one column of 64 node values is then three passes of 4 x 4
// products along w, v and u (256 multiply-adds each; the derivatives
// share passes: 8 in all instead of 3 x 4096 for the dense 192 x 64
// table), each pass four vectors of four points. The results equal the
// dense products up to rounding (a different order of the same sums).
#pragma once

#include <array>
#include <vector>

#include "solver/fem/element_data.h"

namespace dynsolid::fem {

class CubicTensorProducts {
 public:
  // Whether `table` is a cubic element's table on the 4-point rule (the
  // layout's): the only one these products are for.
  static bool Applies(const KindTable& table);
  // The 1D matrices of `table` (Applies(table) must hold).
  explicit CubicTensorProducts(const KindTable& table);

  // out (64 x cols, column major, leading dimension ld_out) = N x, x
  // (64 x cols, column major, leading dimension ld_x): the node values'
  // interpolant at each point.
  void Values(const double* x, int ld_x, int cols, double* out, int ld_out) const;
  // out_c (64 x cols each, leading dimension ld_out) = dN/du_c x for
  // c = u, v, w: the parametric derivatives at each point; with
  // out_values, also Values' result there (one pass more: the values share
  // the derivatives' passes along w and v), the same bits.
  void Derivatives(const double* x, int ld_x, int cols, double* out_u, double* out_v,
                   double* out_w, int ld_out, double* out_values = nullptr) const;
  // The rest Jacobians of rest nodes x (64 x 3) at every point, laid out
  // as fem::RestJacobians lays them out (j[(3 r + c) 64 + q] = J_q(r, c)),
  // from the derivatives above: equal to RestJacobians' up to rounding.
  void Jacobians(const NodeMatrixX3& x, std::vector<double>& j) const;

 private:
  // a_[a][i] = A(a, i), d_[a][i] = A'(a, i).
  std::array<std::array<double, 4>, 4> a_{}, d_{};
};

}  // namespace dynsolid::fem
