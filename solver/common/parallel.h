// Deterministic static work splitting over a few threads for build-time
// (per topology change) work. Chunk k always covers the same index range
// whatever the timing, so callers that write per-chunk outputs and join them
// in chunk order get bit-identical results on any machine.
#pragma once

#include <algorithm>
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

// Calls fn(chunk, begin, end) for `chunks` contiguous ranges covering
// [0, n), chunk 0 on the calling thread, the others on their own threads.
// Ranges smaller than `min_per_chunk` are merged (fewer chunks). Returns the
// number of chunks used.
template <typename Fn>
int ParallelChunks(int64_t n, int chunks, int64_t min_per_chunk, Fn&& fn) {
  chunks = static_cast<int>(std::max<int64_t>(
      1, std::min<int64_t>(chunks, n / std::max<int64_t>(1, min_per_chunk))));
  auto range = [&](int k) { return std::pair<int64_t, int64_t>{n * k / chunks, n * (k + 1) / chunks}; };
  std::vector<std::thread> threads;
  threads.reserve(chunks - 1);
  for (int k = 1; k < chunks; ++k) {
    threads.emplace_back([&fn, &range, k] {
      const auto [b, e] = range(k);
      fn(k, b, e);
    });
  }
  const auto [b, e] = range(0);
  fn(0, b, e);
  for (auto& t : threads) t.join();
  return chunks;
}

}  // namespace dynsolid
