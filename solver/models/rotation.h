// Rotation of a deformation gradient (its polar factor), robust for
// inverted elements: the iterative method of Mueller, Bender, Chentanez and
// Macklin, "A robust method to extract the rotational part of
// deformations" (MIG 2016), warm-started from the previous step's rotation,
// with a Newton step where it is safe.
//
// Each iteration turns R by omega, R <- exp(omega) R, to drive
// num = sum_i r_i x f_i (r_i, f_i the columns of R and F) to zero. Under
// that turn num changes by -(tr(R^T F) I - R F^T) omega, so the Newton step
// solves (tr I - R F^T) omega = num: quadratic convergence. Mueller et al.
// take omega = num / (|tr| + eps) instead, which never fails but only
// converges linearly (about a third of the error per iteration near a
// rotation): a warm start one time step old then runs into the iteration
// cap every step. The Newton step is used only while the symmetric part of
// J = tr I - R F^T is well positive definite (leading minors above (tr/20)^k;
// near a rotation J's eigenvalues are sums of two singular values, so this
// fails only for elements close to inversion), else Mueller's step.
// Small turns (|omega| < 1e-3) update the quaternion to first order and
// renormalize (the iteration corrects the difference), larger ones exactly.
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace dynsolid::models {

// Improves `q` towards the rotation closest to F. Deterministic: a fixed
// iteration cap and a fixed stopping test (Mueller's |omega| < 1e-13). With `r_out`,
// also stores q's rotation matrix.
inline void ExtractRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q,
                            int max_iterations = 8, Eigen::Matrix3d* r_out = nullptr) {
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Vector3d num =
        r.col(0).cross(f.col(0)) + r.col(1).cross(f.col(1)) + r.col(2).cross(f.col(2));
    const double tr = r.col(0).dot(f.col(0)) + r.col(1).dot(f.col(1)) + r.col(2).dot(f.col(2));
    // Stopping test on Mueller's step (cheap; the common case once warm).
    const double den = std::abs(tr) + 1e-12;
    if (num.norm() < 1e-13 * den) {
      if (r_out != nullptr) *r_out = r;
      return;
    }
    Eigen::Matrix3d j = -(r * f.transpose());
    j.diagonal().array() += tr;
    const double a = j(0, 0), b = 0.5 * (j(0, 1) + j(1, 0)), e = j(1, 1);
    const double m = tr / 20;
    const Eigen::Matrix3d js = 0.5 * (j + j.transpose());
    Eigen::Vector3d omega;
    if (tr > 0 && a > m && a * e - b * b > m * m && js.determinant() > m * m * m) {
      omega = j.inverse() * num;
    } else {
      omega = num / den;
    }
    const double w = omega.norm();
    if (w < 1e-3) {
      const Eigen::Quaterniond dq(0, 0.5 * omega.x(), 0.5 * omega.y(), 0.5 * omega.z());
      q.coeffs() += (dq * q).coeffs();
    } else {
      q = Eigen::Quaterniond(Eigen::AngleAxisd(w, omega / w)) * q;
    }
    q.normalize();
  }
  if (r_out != nullptr) *r_out = q.toRotationMatrix();
}

}  // namespace dynsolid::models
