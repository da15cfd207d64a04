#include "solver/fem/quadrature.h"

#include <cassert>
#include <cmath>

namespace dynsolid::fem {

Rule1d GaussLegendre(int n) {
  assert(n >= 1 && n <= 8);
  Rule1d r;
  r.points.resize(n);
  r.weights.resize(n);
  for (int i = 0; i < n; ++i) {
    // Root i of P_n on [-1, 1] (Newton from the Chebyshev-like guess).
    double x = std::cos(M_PI * (i + 0.75) / (n + 0.5));
    double dp = 1.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      if (n == 1) p0 = 1.0;
      dp = n * (x * p1 - p0) / (x * x - 1.0);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-16) break;
    }
    double p0 = 1.0, p1 = x;
    for (int k = 2; k <= n; ++k) {
      const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
      p0 = p1;
      p1 = p2;
    }
    dp = n * (x * p1 - p0) / (x * x - 1.0);
    // Map [-1, 1] -> [0, 1]; weights halve. Ascending order.
    r.points[n - 1 - i] = 0.5 * (x + 1.0);
    r.weights[n - 1 - i] = 1.0 / ((1.0 - x * x) * dp * dp);
  }
  return r;
}

Rule3d GaussLegendreCube(int n) {
  const Rule1d r = GaussLegendre(n);
  Rule3d q;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) {
        q.points.emplace_back(r.points[i], r.points[j], r.points[k]);
        q.weights.push_back(r.weights[i] * r.weights[j] * r.weights[k]);
      }
    }
  }
  return q;
}

}  // namespace dynsolid::fem
