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
// from a warm start. Turns are applied exactly (a series below 0.25 rad,
// an angle-axis rotation above). Both stop when the linear step a / (|tr S| + 1e-12)
// is below 1e-13 rad, or at `max_iterations`. Deterministic.
//
// `newton_exit` > 0 also stops right after a Newton step shorter than it:
// the error left is then of the order of the step's square (1e-10 rad for
// a step of 1e-5), which saves the iteration that would only confirm it.
// For callers whose forces are second order in a frame error (the
// local-frame model rotates the rotation-blind measure delta with the
// frame); the corotational model, first order in it, runs to the test.
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

// q * exp(w) for a body-frame turn w of at most 0.25 rad: the half-angle
// cosine and sin(h)/h as their Taylor series in h^2 (h = |w|/2 <= 0.125;
// the first omitted terms are below 1e-19), so no sine, cosine or division.
inline Eigen::Quaterniond TurnBy(const Eigen::Quaterniond& q, const Eigen::Vector3d& w) {
  const double h2 = 0.25 * w.squaredNorm();
  const double c =
      1 + h2 * (-1.0 / 2 + h2 * (1.0 / 24 + h2 * (-1.0 / 720 + h2 * (1.0 / 40320 - h2 / 3628800))));
  const double s = 0.5 * (1 + h2 * (-1.0 / 6 + h2 * (1.0 / 120 +
                                                     h2 * (-1.0 / 5040 + h2 * (1.0 / 362880 -
                                                                               h2 / 39916800)))));
  return q * Eigen::Quaterniond(c, s * w.x(), s * w.y(), s * w.z());
}

// Improves `q` towards the rotation closest to F (see above). With `r_out`,
// also stores q's rotation matrix.
//
// The Newton system H w = a is solved by H's adjugate (one division; the
// Newton step is taken where H's leading minors show it positive definite,
// the Sylvester form of a Cholesky factorization succeeding), and turns
// up to 0.25 rad by TurnBy: an iteration's chain of dependent square
// roots, divisions, sines and cosines is what a rotation costs, not its
// arithmetic.
inline void ExtractRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q_io,
                            int max_iterations = 8, Eigen::Matrix3d* r_out = nullptr,
                            double newton_exit = 0) {
  // Work on a local copy (kept in registers: the caller's quaternion is
  // written whole and read back a lane at a time, which stalls store
  // forwarding on every iteration).
  Eigen::Quaterniond q = q_io;
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Matrix3d s = r.transpose() * f;
    const Eigen::Vector3d a(s(2, 1) - s(1, 2), s(0, 2) - s(2, 0), s(1, 0) - s(0, 1));
    const double tr = s.trace();
    const double den = std::abs(tr) + 1e-12;
    const double stop = 1e-13 * den;
    if (a.squaredNorm() < stop * stop) {  // the linear step is below 1e-13 rad
      if (r_out != nullptr) *r_out = r;
      q_io = q;
      return;
    }
    // H = tr I - sym(S): w = adj(H) a / det(H) where H is positive definite.
    const double h00 = tr - s(0, 0), h11 = tr - s(1, 1), h22 = tr - s(2, 2);
    const double h10 = -0.5 * (s(1, 0) + s(0, 1)), h20 = -0.5 * (s(2, 0) + s(0, 2)),
                 h21 = -0.5 * (s(2, 1) + s(1, 2));
    const double c00 = h11 * h22 - h21 * h21, c11 = h00 * h22 - h20 * h20,
                 c22 = h00 * h11 - h10 * h10;
    const double c01 = h20 * h21 - h10 * h22, c02 = h10 * h21 - h11 * h20,
                 c12 = h10 * h20 - h00 * h21;
    const double det = h00 * c00 + h10 * c01 + h20 * c02;
    const double tiny = 1e-6 * std::abs(tr) + 1e-300;
    // Cholesky's pivots are h00, c22 / h00 and det / c22.
    bool newton = h00 > tiny && c22 > tiny * h00 && det > tiny * c22;
    Eigen::Vector3d w;
    if (newton) {
      const double id = 1.0 / det;
      w(0) = (c00 * a(0) + c01 * a(1) + c02 * a(2)) * id;
      w(1) = (c01 * a(0) + c11 * a(1) + c12 * a(2)) * id;
      w(2) = (c02 * a(0) + c12 * a(1) + c22 * a(2)) * id;
      newton = w.squaredNorm() <= 0.25 * 0.25;
    }
    if (!newton) w = a / den;  // the linear step, body frame
    const double n2 = w.squaredNorm();
    if (n2 <= 0.25 * 0.25) {
      q = TurnBy(q, w);
    } else {
      const double n = std::sqrt(n2);
      q = q * Eigen::Quaterniond(Eigen::AngleAxisd(n, w / n));
    }
    q.normalize();
    if (newton && n2 < newton_exit * newton_exit) break;
  }
  q_io = q;
  if (r_out != nullptr) *r_out = q.toRotationMatrix();
}

}  // namespace dynsolid::models
