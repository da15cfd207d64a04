// Deterministic work splitting over a few threads for build-time (per
// topology change) work. Part k always covers the same index range
// whatever the timing, so callers that write per-part outputs and join them
// in part order get bit-identical results on any machine.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <thread>
#include <vector>

namespace dynsolid {

// Number of threads for build and step work: the hardware's threads, at
// most 8, at least 1; the environment variable DYNSOLID_THREADS (1-8)
// overrides it (benchmarks, and the tests that check results do not depend
// on it).
inline int BuildThreads() {
  if (const char* env = std::getenv("DYNSOLID_THREADS")) {
    const int n = std::atoi(env);
    if (n >= 1 && n <= 8) return n;
  }
  const unsigned n = std::thread::hardware_concurrency();
  return static_cast<int>(std::clamp(n, 1u, 8u));
}

// Calls fn(thread, part, begin, end) for `parts` contiguous ranges covering
// [0, n) (part k: [n k / parts, n (k + 1) / parts); fewer parts where
// they would hold fewer than `min_per_part`), on up to `threads`
// threads, the calling one among them: each
// thread takes the next part not yet taken, so a thread slowed by other
// work beside it (a build runs several such loops at once) takes fewer
// parts instead of holding the others up. Outputs written per part and
// joined in part order do not depend on the threads or the timing;
// `thread` (0 .. threads - 1) indexes per-thread scratch. Returns the
// number of parts.
template <typename Fn>
int ParallelParts(int64_t n, int threads, int parts, int64_t min_per_part, Fn&& fn) {
  parts = static_cast<int>(std::max<int64_t>(
      1, std::min<int64_t>(parts, n / std::max<int64_t>(1, min_per_part))));
  threads = std::max(1, std::min(threads, parts));
  std::atomic<int> next{0};
  auto work = [&](int t) {
    for (int k = next.fetch_add(1); k < parts; k = next.fetch_add(1)) {
      fn(t, k, n * k / parts, n * (k + 1) / parts);
    }
  };
  std::vector<std::thread> others;
  others.reserve(threads - 1);
  for (int t = 1; t < threads; ++t) others.emplace_back(work, t);
  work(0);
  for (auto& t : others) t.join();
  return parts;
}

}  // namespace dynsolid
