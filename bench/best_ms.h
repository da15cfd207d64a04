// The benchmarks' timer: the best of several rounds, per call.
#pragma once

#include <algorithm>
#include <chrono>

namespace dynsolid::bench {

// Milliseconds per call of `f` in the fastest of `rounds` rounds, each
// calling it `per_round` times.
template <typename F>
double BestMs(int rounds, int per_round, F&& f) {
  using Clock = std::chrono::steady_clock;
  double best = 1e300;
  for (int round = 0; round < rounds; ++round) {
    const auto t0 = Clock::now();
    for (int r = 0; r < per_round; ++r) f();
    best = std::min(best, std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  return best / per_round;
}

}  // namespace dynsolid::bench
