// Shape functions on the unit cube (u, v, w) in [0, 1]^3.
#pragma once

#include <array>

namespace dynsolid::fem {

// Uniform cubic B-spline pieces B_0..B_3 on t in [0, 1] (they sum to 1).
inline std::array<double, 4> CubicBSpline(double t) {
  const double s = 1.0 - t, t2 = t * t, t3 = t2 * t;
  return {s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
          (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0};
}

// Their derivatives d/dt.
inline std::array<double, 4> CubicBSplineDerivative(double t) {
  const double s = 1.0 - t;
  return {-0.5 * s * s, (9.0 * t * t - 12.0 * t) / 6.0,
          (-9.0 * t * t + 6.0 * t + 3.0) / 6.0, 0.5 * t * t};
}

}  // namespace dynsolid::fem
