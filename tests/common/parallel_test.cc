// ParallelParts: every index in exactly one part, parts in their fixed
// ranges whatever thread runs them, per-thread indices in range, and a
// per-part sum joined in part order equal for any thread count.
#include "solver/common/parallel.h"

#include <atomic>
#include <cmath>
#include <mutex>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace dynsolid {
namespace {

TEST(ParallelTest, PartsCoverEveryIndexOnceInTheirFixedRanges) {
  for (int threads : {1, 2, 3, 8}) {
    const int64_t n = 10'007;
    std::vector<std::atomic<int>> hits(n);
    std::vector<std::pair<int64_t, int64_t>> ranges(16, {-1, -1});
    std::mutex mu;
    const int parts = ParallelParts(n, threads, 16, 500, [&](int t, int k, int64_t b, int64_t e) {
      EXPECT_GE(t, 0);
      EXPECT_LT(t, threads);
      for (int64_t i = b; i < e; ++i) hits[i].fetch_add(1);
      std::lock_guard<std::mutex> lock(mu);
      ranges[k] = {b, e};
    });
    EXPECT_EQ(parts, 16);
    for (int64_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "index " << i;
    for (int k = 0; k < parts; ++k) {
      EXPECT_EQ(ranges[k].first, n * k / parts);
      EXPECT_EQ(ranges[k].second, n * (k + 1) / parts);
    }
  }
}

TEST(ParallelTest, SmallRangesMakeFewerParts) {
  int calls = 0;
  EXPECT_EQ(ParallelParts(1500, 2, 16, 512, [&](int, int, int64_t, int64_t) { ++calls; }), 2);
  EXPECT_EQ(calls, 2);
  calls = 0;
  EXPECT_EQ(ParallelParts(0, 2, 16, 512, [&](int, int, int64_t b, int64_t e) {
              ++calls;
              EXPECT_EQ(b, e);
            }),
            1);
  EXPECT_EQ(calls, 1);
}

TEST(ParallelTest, PartSumsJoinedInOrderDoNotDependOnTheThreads) {
  const int64_t n = 100'000;
  auto sum = [&](int threads) {
    std::vector<double> part(16, 0.0);
    const int parts = ParallelParts(n, threads, 16, 1000, [&](int, int k, int64_t b, int64_t e) {
      for (int64_t i = b; i < e; ++i) part[k] += std::sin(0.001 * static_cast<double>(i)) / 3.0;
    });
    double total = 0;
    for (int k = 0; k < parts; ++k) total += part[k];
    return total;
  };
  const double one = sum(1);
  for (int threads : {2, 3, 5, 8}) EXPECT_EQ(sum(threads), one) << threads << " threads";
}

}  // namespace
}  // namespace dynsolid
