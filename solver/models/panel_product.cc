#include "solver/models/panel_product.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define DYNSOLID_PANEL_AVX2 1
#endif

namespace dynsolid::models {
namespace {

constexpr int kColumns = 6;  // columns of Y per micro-kernel call

// The lanes of a micro-kernel: element type T, a register V of kWidth of
// them, and a store that widens to double. A panel is two registers high
// (8 doubles or 16 floats).
#ifdef DYNSOLID_PANEL_AVX2
struct DoubleLanes {
  using T = double;
  using V = __m256d;
  static constexpr int kWidth = 4;
  static V Zero() { return _mm256_setzero_pd(); }
  static V Load(const T* p) { return _mm256_loadu_pd(p); }
  static V Broadcast(const T* p) { return _mm256_broadcast_sd(p); }
  static V Fma(V a, V b, V c) { return _mm256_fmadd_pd(a, b, c); }
  static void Store(double* y, V v) { _mm256_storeu_pd(y, v); }
};
struct FloatLanes {
  using T = float;
  using V = __m256;
  static constexpr int kWidth = 8;
  static V Zero() { return _mm256_setzero_ps(); }
  static V Load(const T* p) { return _mm256_loadu_ps(p); }
  static V Broadcast(const T* p) { return _mm256_broadcast_ss(p); }
  static V Fma(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
  static void Store(double* y, V v) {
    _mm256_storeu_pd(y, _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
    _mm256_storeu_pd(y + 4, _mm256_cvtps_pd(_mm256_extractf128_ps(v, 1)));
  }
};
#else
struct DoubleLanes {
  using T = double;
  static constexpr int kWidth = 4;
};
struct FloatLanes {
  using T = float;
  static constexpr int kWidth = 8;
};
#endif

// y(0:P, 0:NC) = a(P x k panel) x(0:k, 0:NC), P = 2 kWidth rows, stored as
// double. Every entry is one fma chain over k in ascending order.
template <typename L, int NC>
void Kernel(const typename L::T* __restrict a, int k, const typename L::T* __restrict x, int ldx,
            double* __restrict y, int ldy) {
  constexpr int W = L::kWidth;
#ifdef DYNSOLID_PANEL_AVX2
  typename L::V lo[NC], hi[NC];
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) lo[j] = hi[j] = L::Zero();
  for (int kk = 0; kk < k; ++kk) {
    const typename L::V a0 = L::Load(a + 2 * W * kk);
    const typename L::V a1 = L::Load(a + 2 * W * kk + W);
#pragma GCC unroll 6
    for (int j = 0; j < NC; ++j) {
      const typename L::V b = L::Broadcast(x + static_cast<int64_t>(j) * ldx + kk);
      lo[j] = L::Fma(a0, b, lo[j]);
      hi[j] = L::Fma(a1, b, hi[j]);
    }
  }
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) {
    L::Store(y + static_cast<int64_t>(j) * ldy, lo[j]);
    L::Store(y + static_cast<int64_t>(j) * ldy + W, hi[j]);
  }
#else
  // Same fma chains in the same order: the same bits as the AVX2 path.
  using T = typename L::T;
  T c[NC][2 * W] = {};
  for (int kk = 0; kk < k; ++kk) {
    for (int j = 0; j < NC; ++j) {
      const T b = x[static_cast<int64_t>(j) * ldx + kk];
      for (int r = 0; r < 2 * W; ++r) c[j][r] = std::fma(a[2 * W * kk + r], b, c[j][r]);
    }
  }
  for (int j = 0; j < NC; ++j) {
    for (int r = 0; r < 2 * W; ++r) y[static_cast<int64_t>(j) * ldy + r] = c[j][r];
  }
#endif
}

// Runs Kernel over the 6-column tiles of a batch and the panels of a
// packed matrix.
template <typename L>
void Tiles(const typename L::T* data, int panels, int cols, const typename L::T* x, int ldx,
           int count, double* y, int ldy) {
  using T = typename L::T;
  constexpr int P = 2 * L::kWidth;
  const int64_t panel_size = static_cast<int64_t>(cols) * P;
  for (int j0 = 0; j0 < count; j0 += kColumns) {
    const T* xb = x + static_cast<int64_t>(j0) * ldx;
    double* yb = y + static_cast<int64_t>(j0) * ldy;
    const int nc = std::min(kColumns, count - j0);
    for (int p = 0; p < panels; ++p) {
      const T* a = data + p * panel_size;
      double* yp = yb + p * P;
      switch (nc) {
        case 6: Kernel<L, 6>(a, cols, xb, ldx, yp, ldy); break;
        case 5: Kernel<L, 5>(a, cols, xb, ldx, yp, ldy); break;
        case 4: Kernel<L, 4>(a, cols, xb, ldx, yp, ldy); break;
        case 3: Kernel<L, 3>(a, cols, xb, ldx, yp, ldy); break;
        case 2: Kernel<L, 2>(a, cols, xb, ldx, yp, ldy); break;
        default: Kernel<L, 1>(a, cols, xb, ldx, yp, ldy); break;
      }
    }
  }
}

static_assert(2 * DoubleLanes::kWidth == PackedMatrix::kPanel);
static_assert(2 * FloatLanes::kWidth == PackedMatrixF::kPanel);

template <typename T>
using LanesOf = std::conditional_t<std::is_same_v<T, double>, DoubleLanes, FloatLanes>;

// Packs rows x cols entries get(i, j) into panels of P rows (zero padded).
template <typename T, int P, typename Get>
void Pack(int rows, int cols, int panels, const Get& get,
          std::vector<T, Eigen::aligned_allocator<T>>& data) {
  data.assign(static_cast<size_t>(panels) * cols * P, T(0));
  for (int p = 0; p < panels; ++p) {
    for (int j = 0; j < cols; ++j) {
      for (int r = 0; r < P && p * P + r < rows; ++r) {
        data[(static_cast<size_t>(p) * cols + j) * P + r] = static_cast<T>(get(p * P + r, j));
      }
    }
  }
}

// The rows x cols matrix held in panels of P rows, as doubles.
template <typename T, int P>
Eigen::MatrixXd Unpacked(int rows, int cols, int panels,
                         const std::vector<T, Eigen::aligned_allocator<T>>& data) {
  Eigen::MatrixXd k(rows, cols);
  for (int p = 0; p < panels; ++p) {
    for (int j = 0; j < cols; ++j) {
      for (int r = 0; r < P && p * P + r < rows; ++r) {
        k(p * P + r, j) = data[(static_cast<size_t>(p) * cols + j) * P + r];
      }
    }
  }
  return k;
}

}  // namespace

template <typename T>
PackedPanels<T>::PackedPanels(const Eigen::MatrixXd& k)
    : rows_(static_cast<int>(k.rows())),
      cols_(static_cast<int>(k.cols())),
      panels_((rows_ + kPanel - 1) / kPanel) {
  Pack<T, kPanel>(rows_, cols_, panels_, [&](int i, int j) { return k(i, j); }, data_);
}

template <typename T>
Eigen::MatrixXd PackedPanels<T>::Unpack() const {
  return Unpacked<T, kPanel>(rows_, cols_, panels_, data_);
}

template <typename T>
void PackedPanels<T>::Apply(const T* x, int ldx, int count, double* y, int ldy) const {
  Tiles<LanesOf<T>>(data_.data(), panels_, cols_, x, ldx, count, y, ldy);
}

template class PackedPanels<double>;
template class PackedPanels<float>;

}  // namespace dynsolid::models
