#include "solver/models/gram.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace dynsolid::models {

namespace gram_detail {
#if defined(__x86_64__) && defined(__AVX2__) && defined(__FMA__)
namespace avx2 {
void AddPanel(const double* w, int64_t rows, int n, int64_t ldw, const uint64_t* chunks,
              double* g, int64_t ldg);
}
#define DYNSOLID_GRAM_AVX2 1
#endif
#ifdef DYNSOLID_GRAM_AVX512
namespace avx512 {
void AddPanel(const double* w, int64_t rows, int n, int64_t ldw, const uint64_t* chunks,
              double* g, int64_t ldg);
}
#endif
}  // namespace gram_detail

namespace {

// A panel's sums (gram.h), one entry at a time, over the chunks both
// columns may be nonzero in (all where `chunks` is null).
void PortablePanel(const double* w, int64_t rows, int n, int64_t ldw, const uint64_t* chunks,
                   double* g, int64_t ldg) {
  const int64_t count = rows / 8;
  for (int j = 0; j < n; ++j) {
    for (int i = j; i < n; ++i) {
      const double* ci = w + i * ldw;
      const double* cj = w + j * ldw;
      std::array<double, 8> l{};
      for (int64_t c = 0; c < count; ++c) {
        if (chunks != nullptr && ((chunks[i] & chunks[j]) >> c & 1) == 0) continue;
        for (int64_t r = 8 * c; r < 8 * c + 8; ++r) l[r % 8] = std::fma(ci[r], cj[r], l[r % 8]);
      }
      g[i + j * ldg] += ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7]));
    }
  }
}

bool Runs(GramPath path) {
  switch (path) {
    case GramPath::kPortable:
      return true;
    case GramPath::kAvx2:
#ifdef DYNSOLID_GRAM_AVX2
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
      return false;
#endif
    case GramPath::kAvx512:
#ifdef DYNSOLID_GRAM_AVX512
      // __builtin_cpu_supports also asks whether the OS saves the
      // AVX-512 registers.
      return __builtin_cpu_supports("avx512f");
#else
      return false;
#endif
  }
  return false;
}

}  // namespace

void GramStart(int n, double* g, int64_t ldg) {
  for (int j = 0; j < n; ++j) std::fill_n(g + j + j * ldg, n - j, 0.0);
}

bool GramAddPanel(GramPath path, const double* w, int64_t rows, int n, int64_t ldw,
                  const uint64_t* chunks, double* g, int64_t ldg) {
  if (!Runs(path)) return false;
  switch (path) {
    case GramPath::kPortable:
      PortablePanel(w, rows, n, ldw, chunks, g, ldg);
      break;
    case GramPath::kAvx2:
#ifdef DYNSOLID_GRAM_AVX2
      gram_detail::avx2::AddPanel(w, rows, n, ldw, chunks, g, ldg);
#endif
      break;
    case GramPath::kAvx512:
#ifdef DYNSOLID_GRAM_AVX512
      gram_detail::avx512::AddPanel(w, rows, n, ldw, chunks, g, ldg);
#endif
      break;
  }
  return true;
}

bool GramAddPanel(GramPath path, const double* w, int64_t rows, int n, int64_t ldw, double* g,
                  int64_t ldg) {
  return GramAddPanel(path, w, rows, n, ldw, nullptr, g, ldg);
}

void GramAddPanel(const double* w, int64_t rows, int n, int64_t ldw, double* g, int64_t ldg) {
  GramAddPanel(FastestGramPath(), w, rows, n, ldw, nullptr, g, ldg);
}

void GramAddPanel(const double* w, int64_t rows, int n, int64_t ldw, const uint64_t* chunks,
                  double* g, int64_t ldg) {
  GramAddPanel(FastestGramPath(), w, rows, n, ldw, chunks, g, ldg);
}

void GramFinish(int n, double* g, int64_t ldg) {
  for (int j = 0; j < n; ++j) {
    for (int i = j + 1; i < n; ++i) g[j + i * ldg] = g[i + j * ldg];
  }
}

bool Gram(GramPath path, const double* w, int64_t rows, int n, int64_t ldw, double* g,
          int64_t ldg) {
  if (!Runs(path)) return false;
  GramStart(n, g, ldg);
  for (int64_t r0 = 0; r0 < rows; r0 += kGramPanelRows) {
    GramAddPanel(path, w + r0, std::min(rows - r0, kGramPanelRows), n, ldw, g, ldg);
  }
  GramFinish(n, g, ldg);
  return true;
}

GramPath FastestGramPath() {
  static const GramPath fastest = [] {
    for (GramPath p : {GramPath::kAvx512, GramPath::kAvx2}) {
      if (Runs(p)) return p;
    }
    return GramPath::kPortable;
  }();
  return fastest;
}

void Gram(const double* w, int64_t rows, int n, int64_t ldw, double* g, int64_t ldg) {
  Gram(FastestGramPath(), w, rows, n, ldw, g, ldg);
}

const char* GramPathName(GramPath path) {
  switch (path) {
    case GramPath::kPortable:
      return "portable";
    case GramPath::kAvx2:
      return "avx2";
    case GramPath::kAvx512:
      return "avx512";
  }
  return "?";
}

}  // namespace dynsolid::models
