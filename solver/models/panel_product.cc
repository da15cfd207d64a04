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

}  // namespace

PackedMatrix::PackedMatrix(const Eigen::MatrixXd& k)
    : rows_(static_cast<int>(k.rows())),
      cols_(static_cast<int>(k.cols())),
      panels_((rows_ + kPanel - 1) / kPanel) {
  data_.assign(static_cast<size_t>(panels_) * cols_ * kPanel, 0.0);
  for (int p = 0; p < panels_; ++p) {
    for (int j = 0; j < cols_; ++j) {
      for (int r = 0; r < kPanel && p * kPanel + r < rows_; ++r) {
        data_[(static_cast<size_t>(p) * cols_ + j) * kPanel + r] = k(p * kPanel + r, j);
      }
    }
  }
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
  const int64_t panel_size = static_cast<int64_t>(cols_) * kPanel;
  for (int j0 = 0; j0 < count; j0 += kColumns) {
    const double* xb = x + static_cast<int64_t>(j0) * ldx;
    double* yb = y + static_cast<int64_t>(j0) * ldy;
    const int nc = std::min(kColumns, count - j0);
    for (int p = 0; p < panels_; ++p) {
      const double* a = data_.data() + p * panel_size;
      double* yp = yb + p * kPanel;
      switch (nc) {
        case 6: Kernel<6>(a, cols_, xb, ldx, yp, ldy); break;
        case 5: Kernel<5>(a, cols_, xb, ldx, yp, ldy); break;
        case 4: Kernel<4>(a, cols_, xb, ldx, yp, ldy); break;
        case 3: Kernel<3>(a, cols_, xb, ldx, yp, ldy); break;
        case 2: Kernel<2>(a, cols_, xb, ldx, yp, ldy); break;
        default: Kernel<1>(a, cols_, xb, ldx, yp, ldy); break;
      }
    }
  }
}

}  // namespace dynsolid::models
