// Order statistics for reports (the server's step and latency figures, the
// benchmarks', dynsolid-sim's): one Percentile and one Median for every
// side of the walls that may see the solver. Clients have the client
// library's (clients/lib/stats.h), the same nearest rank: they never see
// the solver. Header-only, standard library only, so the standalone
// VegaFEM driver (bench/vega/) uses it too.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace dynsolid {

// Nearest rank: the smallest value with at least q (in [0, 1]) of the
// values at or below it; 0 when empty.
inline double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double rank = std::ceil(q * static_cast<double>(v.size()));
  const size_t k = static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(v.size()))) - 1;
  return v[k];
}

// The middle value (the mean of the two middle ones for an even count); 0
// when empty.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace dynsolid
