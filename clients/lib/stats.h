// Order statistics for the clients' reports (dynsolid-client, the load
// tester, the haptic bridge). The same nearest rank as the server's
// (solver/common/stats.h), written again here because clients never see
// the solver.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace dynsolid::client {

// Nearest rank: the smallest value with at least p (in [0, 1]) of the
// values at or below it; 0 when empty.
inline double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const double rank = std::ceil(p * static_cast<double>(values.size()));
  const size_t i = static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(values.size()))) - 1;
  return values[i];
}

}  // namespace dynsolid::client
