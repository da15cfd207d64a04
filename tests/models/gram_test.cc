#include "solver/models/gram.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "tests/models/random_matrix.h"

namespace dynsolid::models {
namespace {

// The sizes around the blocks (4 x 4, 3 x 2), the panels (512 rows) and
// the cells' W (a couple of thousand rows, 3 S columns).
struct Case {
  int64_t rows;
  int n;
};
const Case kCases[] = {{8, 1},    {8, 2},     {16, 5},    {64, 7},     {512, 12},  {520, 13},
                       {1024, 17}, {1000, 33}, {2304, 96}, {1856, 111}, {304, 168}};

TEST(GramTest, EqualsWTransposeWAndIsSymmetricToTheBit) {
  for (const Case& c : kCases) {
    const int64_t ldw = c.rows + 5;  // a leading dimension past the rows
    const Eigen::MatrixXd w = RandomMatrix(ldw, c.n, 3u + c.n);
    const int64_t ldg = c.n + 2;
    Eigen::MatrixXd g = Eigen::MatrixXd::Constant(ldg, c.n, 99.0);
    Gram(w.data(), c.rows, c.n, ldw, g.data(), ldg);
    const Eigen::MatrixXd want = w.topRows(c.rows).transpose() * w.topRows(c.rows);
    for (int j = 0; j < c.n; ++j) {
      for (int i = 0; i < c.n; ++i) {
        EXPECT_NEAR(g(i, j), want(i, j), 1e-14 * static_cast<double>(c.rows))
            << "rows " << c.rows << " n " << c.n << " at " << i << ", " << j;
        EXPECT_EQ(g(i, j), g(j, i));
      }
      for (int i = c.n; i < ldg; ++i) EXPECT_EQ(g(i, j), 99.0) << "past n: untouched";
    }
  }
}

// Every path this machine runs gives the portable path's bits (gram.h's
// sum is defined, not left to the kernel): a journal replayed on a CPU
// with another instruction set rebuilds the same matrices.
TEST(GramTest, EveryPathGivesThePortableBits) {
  int ran = 0;
  for (GramPath path : {GramPath::kAvx2, GramPath::kAvx512}) {
    for (const Case& c : kCases) {
      const Eigen::MatrixXd w = RandomMatrix(c.rows, c.n, 17u + c.n);
      Eigen::MatrixXd portable(c.n, c.n), other(c.n, c.n);
      ASSERT_TRUE(Gram(GramPath::kPortable, w.data(), c.rows, c.n, c.rows, portable.data(), c.n));
      if (!Gram(path, w.data(), c.rows, c.n, c.rows, other.data(), c.n)) break;
      ++ran;
      EXPECT_EQ(std::memcmp(portable.data(), other.data(), sizeof(double) * c.n * c.n), 0)
          << GramPathName(path) << " rows " << c.rows << " n " << c.n;
    }
  }
  // Each path that runs here ran every case (none on a CPU without AVX2).
  EXPECT_EQ(ran % std::size(kCases), 0u);
  std::printf("fastest Gram path here: %s\n", GramPathName(FastestGramPath()));
}

// The lanes and panels are gram.h's: one row gives its products rounded
// once; eight rows, lane by lane, the fixed tree of their products; and
// rows of zeros appended (the callers' padding) change no bit.
TEST(GramTest, TheSumIsTheDefinedOne) {
  const int n = 9;
  Eigen::MatrixXd w = RandomMatrix(2048, n, 5u);
  Eigen::MatrixXd one(n, n);
  w.bottomRows(2048 - 8).setZero();
  w.middleRows(1, 7).setZero();
  Gram(w.data(), 8, n, 2048, one.data(), n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) EXPECT_EQ(one(i, j), w(0, i) * w(0, j));
  }
  w = RandomMatrix(2048, n, 6u);
  Eigen::MatrixXd eight(n, n);
  Gram(w.data(), 8, n, 2048, eight.data(), n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      double l[8];
      for (int r = 0; r < 8; ++r) l[r] = std::fma(w(r, i), w(r, j), 0.0);  // rounded: no add fuses it
      EXPECT_EQ(eight(i, j), ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7])));
    }
  }
  w.bottomRows(2048 - 600).setZero();
  Eigen::MatrixXd whole(n, n), first(n, n);
  Gram(w.data(), 2048, n, 2048, whole.data(), n);
  Gram(w.data(), 600, n, 2048, first.data(), n);
  EXPECT_EQ(std::memcmp(whole.data(), first.data(), sizeof(double) * n * n), 0);
}

// A caller keeping one panel of rows at a time (each in a buffer of its
// own) gets Gram's bits on every path.
TEST(GramTest, PanelAtATimeGivesGramsBits) {
  const int64_t rows = 3 * kGramPanelRows + 40;
  const int n = 21;
  const Eigen::MatrixXd w = RandomMatrix(rows, n, 9u);
  for (GramPath path : {GramPath::kPortable, GramPath::kAvx2, GramPath::kAvx512}) {
    Eigen::MatrixXd whole(n, n), panels(n, n);
    if (!Gram(path, w.data(), rows, n, rows, whole.data(), n)) continue;
    GramStart(n, panels.data(), n);
    for (int64_t r0 = 0; r0 < rows; r0 += kGramPanelRows) {
      const int64_t count = std::min(kGramPanelRows, rows - r0);
      const Eigen::MatrixXd panel = w.middleRows(r0, count);  // its own buffer
      ASSERT_TRUE(GramAddPanel(path, panel.data(), count, n, count, panels.data(), n));
    }
    GramFinish(n, panels.data(), n);
    EXPECT_EQ(std::memcmp(whole.data(), panels.data(), sizeof(double) * n * n), 0)
        << GramPathName(path);
  }
}

// A panel whose columns are zero outside given chunks of 8 rows (a cell's
// elements outside their support): the masked sum gives the unmasked
// one's bits on every path. Masks of runs, scattered chunks, empty
// columns, full columns, and bits past a short last panel's rows.
TEST(GramTest, ChunkMasksSkipZerosAndKeepTheBits) {
  const int64_t rows = 2 * kGramPanelRows + 40;
  const int n = 23;
  Eigen::MatrixXd w = RandomMatrix(rows, n, 11u);
  std::vector<std::vector<uint64_t>> masks;  // per panel, per column
  uint64_t state = 0x9e3779b97f4a7c15ull;
  auto next = [&] {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
  };
  for (int64_t r0 = 0; r0 < rows; r0 += kGramPanelRows) {
    std::vector<uint64_t>& m = masks.emplace_back(n);
    for (int c = 0; c < n; ++c) {
      switch (c % 5) {
        case 0: m[c] = next() & next(); break;                  // scattered
        case 1: m[c] = (~uint64_t{0} >> (c % 64)) << (c % 7); break;  // a run
        case 2: m[c] = c % 2 == 0 ? 0 : ~uint64_t{0}; break;    // none or all
        default: m[c] = next(); break;
      }
    }
  }
  Eigen::MatrixXd zeroed = w;
  for (size_t p = 0; p < masks.size(); ++p) {
    for (int c = 0; c < n; ++c) {
      for (int64_t r = 0; r < kGramPanelRows && p * kGramPanelRows + r < rows; ++r) {
        if ((masks[p][c] >> (r / 8) & 1) != 0) continue;
        zeroed(p * kGramPanelRows + r, c) = 0;
      }
    }
  }
  int ran = 0;
  for (GramPath path : {GramPath::kPortable, GramPath::kAvx2, GramPath::kAvx512}) {
    Eigen::MatrixXd whole(n, n), masked(n, n);
    if (!Gram(path, zeroed.data(), rows, n, rows, whole.data(), n)) continue;
    ++ran;
    GramStart(n, masked.data(), n);
    for (size_t p = 0; p < masks.size(); ++p) {
      const int64_t r0 = static_cast<int64_t>(p) * kGramPanelRows;
      const int64_t count = std::min(kGramPanelRows, rows - r0);
      ASSERT_TRUE(GramAddPanel(path, zeroed.data() + r0, count, n, rows, masks[p].data(),
                               masked.data(), n));
    }
    GramFinish(n, masked.data(), n);
    EXPECT_EQ(std::memcmp(whole.data(), masked.data(), sizeof(double) * n * n), 0)
        << GramPathName(path);
    // Columns zero in every panel have zero rows and columns of G.
    EXPECT_EQ(masked(2, 2), 0.0);
    EXPECT_EQ(masked(7, 2), 0.0);
  }
  EXPECT_GE(ran, 1);
}

}  // namespace
}  // namespace dynsolid::models
