// Sum factorization of a cubic element group's local-frame matrices.
//
// A cubic B-spline element whose rest map is an axis-aligned box (x =
// x0 + diag(h) P u for a permutation P) with one material throughout has
// K_a = sum_d c_ad T_d (a = x, y, z; d = u, v, w): T_u = D (x) M (x) M,
// T_v = M (x) D (x) M, T_w = M (x) M (x) D, where M and D are the 4 x 4
// integrals of the 1D B-spline pieces' products and of their derivatives'
// products under the element's own 1D Gauss rule (the 3D rule is its
// tensor product, so the factorization is exact, not an approximation).
// Node m = 16 i + 4 j + k carries u index i, v index j, w index k
// (fem::CubicShape).
//
// Applying K_a then takes 1D products along each axis in turn,
//   A = M_w X, B = D_w X; C = M_v A, E = D_v A, F = M_v B;
//   Y = (c_au D)_u C + M_u (c_av E + c_aw F),
// about 60 % of the instructions of the dense 64 x 64 product, with every
// intermediate in registers or L1 (the dense product streams its 16 KB
// matrix per component).
//
// Fit() finds the c_ad from a group's matrices by least squares on the
// three T_d and accepts them only if they reproduce every entry of the
// matrices to 1e-10 of the largest (a distorted element, a graded
// material or an inexact rule leaves a residual and keeps the dense
// product).
#pragma once

#include <array>
#include <optional>
#include <vector>

#include <Eigen/Core>

namespace dynsolid::models {

// The 1D matrices M and D of a rule and the three 64 x 64 T_d built from
// them, with their Gram matrix: computed once per model, shared by every
// group's fit.
struct KroneckerBasis {
  Eigen::Matrix4d m, d;
  std::array<Eigen::MatrixXd, 3> t;
  Eigen::Matrix3d gram;
  // The 1D rule (points in [0, 1], weights) the elements were integrated
  // with.
  static KroneckerBasis Make(const std::vector<double>& points,
                             const std::vector<double>& weights);
};

class KroneckerStiffness {
 public:
  // The factorization of a group's three 64 x 64 matrices (axis x, y, z),
  // or nothing when they are not of that form.
  static std::optional<KroneckerStiffness> Fit(const KroneckerBasis& basis,
                                                const std::array<Eigen::MatrixXd, 3>& k);

  // The coefficient c_ad (a: axis of the matrix, d: parametric direction).
  double coefficient(int axis, int direction) const { return c_[axis][direction]; }
  // The dense matrix the factorization stands for (tests).
  Eigen::MatrixXd Dense(const KroneckerBasis& basis, int axis) const;

  // y (64 x count, column stride ld, doubles) = K_axis x (64 x count,
  // column stride ld, floats): single-precision arithmetic, results
  // widened to double, as the dense float kernel (panel_product.h). AVX2
  // where the build has it.
  void Apply(int axis, const float* x, int ld, int count, double* y) const;
  // The same steps one value at a time (the path of builds without AVX2;
  // tests hold the two to each other).
  void ApplyPortable(int axis, const float* x, int ld, int count, double* y) const;

 private:
  std::array<std::array<double, 3>, 3> c_{};
  // Float copies for Apply: per axis the scaled D (c_au D), and M and D,
  // row-major; per axis c_av and c_aw.
  std::array<std::array<float, 16>, 3> cd_{};
  std::array<float, 16> mf_{}, df_{};
  std::array<std::array<float, 2>, 3> cvw_{};
};

}  // namespace dynsolid::models
