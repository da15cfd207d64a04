// Rotation of a deformation gradient (its polar factor), robust for
// inverted elements, warm-started from the previous step's rotation.
//
// ExtractRotationLinear is the iteration of Mueller, Bender, Chentanez and
// Macklin, "A robust method to extract the rotational part of deformations"
// (MIG 2016): it converges from any start, but only linearly (the error
// shrinks by about 3 per iteration near a rotation), so a warm start one
// time step old (1e-3 rad away) needs some 20 iterations to reach its
// stopping test and runs into any sensible cap every step.
//
// ExtractRotation (the one the models use) takes Newton steps where they
// are safe. With S = R^T F, a the axial vector of S's skew part and
// H = tr(S) I - sym(S), the body-frame correction is w = H^-1 a,
// R <- R exp(w) (the first-order condition skew(exp(-w) S) = 0; near a
// rotation H's eigenvalues are sums of two singular values). Far from the
// answer (H not positive definite, or a step above 0.25 rad) it takes the
// linear iteration's step instead. Quadratic convergence: 2-3 iterations
// from a warm start. Small turns (below 1e-3 rad) update the quaternion to
// first order and renormalize (the next iteration corrects the difference),
// larger ones exactly. Both stop when the linear step a / (|tr S| + 1e-12)
// is below 1e-13 rad, or at `max_iterations`. Deterministic.
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace dynsolid::models {

// Mueller et al.'s iteration (the reference; see above).
inline void ExtractRotationLinear(const Eigen::Matrix3d& f, Eigen::Quaterniond& q,
                                  int max_iterations = 8) {
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Vector3d num =
        r.col(0).cross(f.col(0)) + r.col(1).cross(f.col(1)) + r.col(2).cross(f.col(2));
    const double den =
        std::abs(r.col(0).dot(f.col(0)) + r.col(1).dot(f.col(1)) + r.col(2).dot(f.col(2))) +
        1e-12;
    const Eigen::Vector3d omega = num / den;
    const double w = omega.norm();
    if (w < 1e-13) break;
    q = Eigen::Quaterniond(Eigen::AngleAxisd(w, omega / w)) * q;
    q.normalize();
  }
}

// Improves `q` towards the rotation closest to F (see above). With `r_out`,
// also stores q's rotation matrix.
inline void ExtractRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q,
                            int max_iterations = 8, Eigen::Matrix3d* r_out = nullptr) {
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Matrix3d s = r.transpose() * f;
    const Eigen::Vector3d a(s(2, 1) - s(1, 2), s(0, 2) - s(2, 0), s(1, 0) - s(0, 1));
    const double tr = s.trace();
    const double den = std::abs(tr) + 1e-12;
    if (a.norm() < 1e-13 * den) {  // the linear step is below 1e-13 rad
      if (r_out != nullptr) *r_out = r;
      return;
    }
    // H = tr I - sym(S), solved by a 3 x 3 Cholesky factorization.
    const double h00 = tr - s(0, 0), h11 = tr - s(1, 1), h22 = tr - s(2, 2);
    const double h10 = -0.5 * (s(1, 0) + s(0, 1)), h20 = -0.5 * (s(2, 0) + s(0, 2)),
                 h21 = -0.5 * (s(2, 1) + s(1, 2));
    Eigen::Vector3d w;
    bool newton = false;
    const double tiny = 1e-6 * std::abs(tr) + 1e-300;
    if (h00 > tiny) {
      const double l00 = std::sqrt(h00), l10 = h10 / l00, l20 = h20 / l00;
      const double d11 = h11 - l10 * l10;
      if (d11 > tiny) {
        const double l11 = std::sqrt(d11), l21 = (h21 - l20 * l10) / l11;
        const double d22 = h22 - l20 * l20 - l21 * l21;
        if (d22 > tiny) {
          const double l22 = std::sqrt(d22);
          // L y = a, L^T w = y.
          const double y0 = a(0) / l00, y1 = (a(1) - l10 * y0) / l11,
                       y2 = (a(2) - l20 * y0 - l21 * y1) / l22;
          w(2) = y2 / l22;
          w(1) = (y1 - l21 * w(2)) / l11;
          w(0) = (y0 - l10 * w(1) - l20 * w(2)) / l00;
          newton = w.squaredNorm() <= 0.25 * 0.25;
        }
      }
    }
    if (!newton) w = a / den;  // the linear step, body frame
    const double n = w.norm();
    if (n < 1e-3) {
      const Eigen::Quaterniond dq(0, 0.5 * w.x(), 0.5 * w.y(), 0.5 * w.z());
      q.coeffs() += (q * dq).coeffs();
    } else {
      q = q * Eigen::Quaterniond(Eigen::AngleAxisd(n, w / n));
    }
    q.normalize();
  }
  if (r_out != nullptr) *r_out = q.toRotationMatrix();
}

}  // namespace dynsolid::models
