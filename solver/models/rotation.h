// Rotation of a deformation gradient (its polar factor), robust for
// inverted elements: the iterative method of Mueller, Bender, Chentanez and
// Macklin, "A robust method to extract the rotational part of
// deformations" (MIG 2016), warm-started from the previous step's rotation.
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace dynsolid::models {

// Improves `q` towards the rotation closest to F. Deterministic: a fixed
// iteration cap and a fixed stopping test. With `r_out`, also stores q's
// rotation matrix (the one the stopping test computed, when it stopped).
inline void ExtractRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q,
                            int max_iterations = 8, Eigen::Matrix3d* r_out = nullptr) {
  for (int it = 0; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Vector3d num =
        r.col(0).cross(f.col(0)) + r.col(1).cross(f.col(1)) + r.col(2).cross(f.col(2));
    const double den =
        std::abs(r.col(0).dot(f.col(0)) + r.col(1).dot(f.col(1)) + r.col(2).dot(f.col(2))) +
        1e-12;
    const Eigen::Vector3d omega = num / den;
    const double w = omega.norm();
    if (w < 1e-13) {
      if (r_out != nullptr) *r_out = r;
      return;
    }
    q = Eigen::Quaterniond(Eigen::AngleAxisd(w, omega / w)) * q;
    q.normalize();
  }
  if (r_out != nullptr) *r_out = q.toRotationMatrix();
}

}  // namespace dynsolid::models
