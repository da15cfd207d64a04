// The benchmarks' figures: the median of a run's samples, and the peak
// resident memory of the process. Header-only, so the standalone VegaFEM
// driver (bench/vega/) reads the very same memory figure as dynsolid's
// benchmarks.
#pragma once

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace dynsolid::bench {

// The middle sample (the upper of the two middle ones for an even count);
// 0 for none.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// This process's peak resident set so far (VmHWM in /proc/self/status), MB;
// -1 where the kernel does not say.
inline double PeakRssMb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  }
  return -1;
}

}  // namespace dynsolid::bench
