#include "solver/models/panel_product.h"

#include <algorithm>
#include <cmath>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define DYNSOLID_PANEL_AVX2 1
#endif

namespace dynsolid::models {
namespace {

constexpr int kPanel = PackedMatrix::kPanel;
constexpr int kColumns = 6;  // columns of Y per micro-kernel call

// y(0:8, 0:NC) = a(8 x k panel) x(0:k, 0:NC).
template <int NC>
void Kernel(const double* __restrict a, int k, const double* __restrict x, int ldx,
            double* __restrict y, int ldy) {
#ifdef DYNSOLID_PANEL_AVX2
  __m256d lo[NC], hi[NC];
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) lo[j] = hi[j] = _mm256_setzero_pd();
  for (int kk = 0; kk < k; ++kk) {
    const __m256d a0 = _mm256_loadu_pd(a + kPanel * kk);
    const __m256d a1 = _mm256_loadu_pd(a + kPanel * kk + 4);
#pragma GCC unroll 6
    for (int j = 0; j < NC; ++j) {
      const __m256d b = _mm256_broadcast_sd(x + static_cast<int64_t>(j) * ldx + kk);
      lo[j] = _mm256_fmadd_pd(a0, b, lo[j]);
      hi[j] = _mm256_fmadd_pd(a1, b, hi[j]);
    }
  }
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) {
    _mm256_storeu_pd(y + static_cast<int64_t>(j) * ldy, lo[j]);
    _mm256_storeu_pd(y + static_cast<int64_t>(j) * ldy + 4, hi[j]);
  }
#else
  // Same fma chains in the same order: the same bits as the AVX2 path.
  double c[NC][kPanel] = {};
  for (int kk = 0; kk < k; ++kk) {
    for (int j = 0; j < NC; ++j) {
      const double b = x[static_cast<int64_t>(j) * ldx + kk];
      for (int r = 0; r < kPanel; ++r) c[j][r] = std::fma(a[kPanel * kk + r], b, c[j][r]);
    }
  }
  for (int j = 0; j < NC; ++j) {
    for (int r = 0; r < kPanel; ++r) y[static_cast<int64_t>(j) * ldy + r] = c[j][r];
  }
#endif
}

constexpr int kPanelF = PackedMatrixF::kPanel;

// y(0:16, 0:NC) = a(16 x k float panel) x(0:k, 0:NC) (float), stored as double.
template <int NC>
void KernelF(const float* __restrict a, int k, const float* __restrict x, int ldx,
             double* __restrict y, int ldy) {
#ifdef DYNSOLID_PANEL_AVX2
  __m256 lo[NC], hi[NC];
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) lo[j] = hi[j] = _mm256_setzero_ps();
  for (int kk = 0; kk < k; ++kk) {
    const __m256 a0 = _mm256_loadu_ps(a + kPanelF * kk);
    const __m256 a1 = _mm256_loadu_ps(a + kPanelF * kk + 8);
#pragma GCC unroll 6
    for (int j = 0; j < NC; ++j) {
      const __m256 b = _mm256_broadcast_ss(x + static_cast<int64_t>(j) * ldx + kk);
      lo[j] = _mm256_fmadd_ps(a0, b, lo[j]);
      hi[j] = _mm256_fmadd_ps(a1, b, hi[j]);
    }
  }
#pragma GCC unroll 6
  for (int j = 0; j < NC; ++j) {
    double* yj = y + static_cast<int64_t>(j) * ldy;
    _mm256_storeu_pd(yj, _mm256_cvtps_pd(_mm256_castps256_ps128(lo[j])));
    _mm256_storeu_pd(yj + 4, _mm256_cvtps_pd(_mm256_extractf128_ps(lo[j], 1)));
    _mm256_storeu_pd(yj + 8, _mm256_cvtps_pd(_mm256_castps256_ps128(hi[j])));
    _mm256_storeu_pd(yj + 12, _mm256_cvtps_pd(_mm256_extractf128_ps(hi[j], 1)));
  }
#else
  float c[NC][kPanelF] = {};
  for (int kk = 0; kk < k; ++kk) {
    for (int j = 0; j < NC; ++j) {
      const float b = x[static_cast<int64_t>(j) * ldx + kk];
      for (int r = 0; r < kPanelF; ++r) c[j][r] = std::fma(a[kPanelF * kk + r], b, c[j][r]);
    }
  }
  for (int j = 0; j < NC; ++j) {
    for (int r = 0; r < kPanelF; ++r) y[static_cast<int64_t>(j) * ldy + r] = c[j][r];
  }
#endif
}

// Runs Kernel over the 6-column tiles of a batch and the panels of a
// packed matrix (panel_size elements apart).
template <typename T, typename Y, int P, template <int> class K>
void Tiles(const T* data, int panels, int cols, const T* x, int ldx, int count, Y* y, int ldy) {
  const int64_t panel_size = static_cast<int64_t>(cols) * P;
  for (int j0 = 0; j0 < count; j0 += kColumns) {
    const T* xb = x + static_cast<int64_t>(j0) * ldx;
    Y* yb = y + static_cast<int64_t>(j0) * ldy;
    const int nc = std::min(kColumns, count - j0);
    for (int p = 0; p < panels; ++p) {
      const T* a = data + p * panel_size;
      Y* yp = yb + p * P;
      switch (nc) {
        case 6: K<6>::Run(a, cols, xb, ldx, yp, ldy); break;
        case 5: K<5>::Run(a, cols, xb, ldx, yp, ldy); break;
        case 4: K<4>::Run(a, cols, xb, ldx, yp, ldy); break;
        case 3: K<3>::Run(a, cols, xb, ldx, yp, ldy); break;
        case 2: K<2>::Run(a, cols, xb, ldx, yp, ldy); break;
        default: K<1>::Run(a, cols, xb, ldx, yp, ldy); break;
      }
    }
  }
}

template <int NC>
struct DoubleKernel {
  static void Run(const double* a, int k, const double* x, int ldx, double* y, int ldy) {
    Kernel<NC>(a, k, x, ldx, y, ldy);
  }
};
template <int NC>
struct FloatKernel {
  static void Run(const float* a, int k, const float* x, int ldx, double* y, int ldy) {
    KernelF<NC>(a, k, x, ldx, y, ldy);
  }
};

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

}  // namespace

PackedMatrix::PackedMatrix(const Eigen::MatrixXd& k)
    : rows_(static_cast<int>(k.rows())),
      cols_(static_cast<int>(k.cols())),
      panels_((rows_ + kPanel - 1) / kPanel) {
  Pack<double, kPanel>(rows_, cols_, panels_, [&](int i, int j) { return k(i, j); }, data_);
}

Eigen::MatrixXd PackedMatrix::Unpack() const {
  Eigen::MatrixXd k(rows_, cols_);
  for (int p = 0; p < panels_; ++p) {
    for (int j = 0; j < cols_; ++j) {
      for (int r = 0; r < kPanel && p * kPanel + r < rows_; ++r) {
        k(p * kPanel + r, j) = data_[(static_cast<size_t>(p) * cols_ + j) * kPanel + r];
      }
    }
  }
  return k;
}

void PackedMatrix::Apply(const double* x, int ldx, int count, double* y, int ldy) const {
  Tiles<double, double, kPanel, DoubleKernel>(data_.data(), panels_, cols_, x, ldx, count, y, ldy);
}

PackedMatrixF::PackedMatrixF(const PackedMatrix& k)
    : rows_(k.rows()), cols_(k.cols()), panels_((rows_ + kPanel - 1) / kPanel) {
  const Eigen::MatrixXd full = k.Unpack();
  Pack<float, kPanel>(rows_, cols_, panels_, [&](int i, int j) { return full(i, j); }, data_);
}

void PackedMatrixF::Apply(const float* x, int ldx, int count, double* y, int ldy) const {
  Tiles<float, double, kPanel, FloatKernel>(data_.data(), panels_, cols_, x, ldx, count, y, ldy);
}

}  // namespace dynsolid::models
