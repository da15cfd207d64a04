#include "solver/models/kron_product.h"

#include <Eigen/Dense>

#include "solver/fem/basis.h"
#include "solver/fem/element_set.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define DYNSOLID_KRON_AVX2 1
#endif

namespace dynsolid::models {
namespace {

constexpr int kN = fem::kCubicNodes;  // the 4 x 4 x 4 tensor-ordered nodes

// T_d (64 x 64): the 1D matrix `a` on direction d's factor and `m` on the
// other two (node m = 16 i + 4 j + k: i along u, j along v, k along w).
Eigen::MatrixXd Tensor(int d, const Eigen::Matrix4d& m, const Eigen::Matrix4d& a) {
  const Eigen::Matrix4d& fu = d == 0 ? a : m;
  const Eigen::Matrix4d& fv = d == 1 ? a : m;
  const Eigen::Matrix4d& fw = d == 2 ? a : m;
  Eigen::MatrixXd t(kN, kN);
  for (int r = 0; r < kN; ++r) {
    for (int c = 0; c < kN; ++c) {
      t(r, c) = fu(r / 16, c / 16) * fv((r / 4) % 4, (c / 4) % 4) * fw(r % 4, c % 4);
    }
  }
  return t;
}

}  // namespace

KroneckerBasis KroneckerBasis::Make(const std::vector<double>& points,
                                    const std::vector<double>& weights) {
  KroneckerBasis basis;
  basis.m.setZero();
  basis.d.setZero();
  for (size_t q = 0; q < points.size(); ++q) {
    const std::array<double, 4> b = fem::CubicBSpline(points[q]);
    const std::array<double, 4> db = fem::CubicBSplineDerivative(points[q]);
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) {
        basis.m(i, j) += weights[q] * b[i] * b[j];
        basis.d(i, j) += weights[q] * db[i] * db[j];
      }
    }
  }
  for (int d = 0; d < 3; ++d) basis.t[d] = Tensor(d, basis.m, basis.d);
  for (int d = 0; d < 3; ++d)
    for (int e = 0; e < 3; ++e) basis.gram(d, e) = basis.t[d].cwiseProduct(basis.t[e]).sum();
  return basis;
}

std::optional<KroneckerStiffness> KroneckerStiffness::Fit(const KroneckerBasis& basis,
                                                          const std::array<Eigen::MatrixXd, 3>& k) {
  for (const Eigen::MatrixXd& m : k) {
    if (m.rows() != kN || m.cols() != kN) return std::nullopt;
  }
  KroneckerStiffness s;
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector3d rhs;
    for (int d = 0; d < 3; ++d) rhs[d] = k[a].cwiseProduct(basis.t[d]).sum();
    const Eigen::Vector3d c = basis.gram.ldlt().solve(rhs);
    const double scale = k[a].cwiseAbs().maxCoeff();
    const double residual =
        (k[a] - c[0] * basis.t[0] - c[1] * basis.t[1] - c[2] * basis.t[2]).cwiseAbs().maxCoeff();
    if (!(scale > 0) || !(residual <= 1e-10 * scale)) return std::nullopt;
    for (int d = 0; d < 3; ++d) s.c_[a][d] = c[d];
  }
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      s.mf_[4 * i + j] = static_cast<float>(basis.m(i, j));
      s.df_[4 * i + j] = static_cast<float>(basis.d(i, j));
      for (int a = 0; a < 3; ++a) {
        s.cd_[a][4 * i + j] = static_cast<float>(s.c_[a][0] * basis.d(i, j));
      }
    }
  }
  for (int a = 0; a < 3; ++a) {
    s.cvw_[a] = {static_cast<float>(s.c_[a][1]), static_cast<float>(s.c_[a][2])};
  }
  return s;
}

Eigen::MatrixXd KroneckerStiffness::Dense(const KroneckerBasis& basis, int axis) const {
  return c_[axis][0] * basis.t[0] + c_[axis][1] * basis.t[1] + c_[axis][2] * basis.t[2];
}

namespace {

#ifdef DYNSOLID_KRON_AVX2
// Register r (0..7) of an element's 64 floats holds nodes 8 r .. 8 r + 7:
// u index i = r / 2; its lower 128 bits v index j = 2 (r % 2), its upper
// j + 1; lane l % 4 the w index k.

// Along w (within each 4-float half): out_k = sum_k' a(k, k') x_k'.
struct AlongW {
  __m256 col[4];  // col[k'] lanes: a(0..3, k') in both halves
  explicit AlongW(const float* a) {
    for (int kp = 0; kp < 4; ++kp) {
      col[kp] = _mm256_setr_ps(a[kp], a[4 + kp], a[8 + kp], a[12 + kp], a[kp], a[4 + kp],
                               a[8 + kp], a[12 + kp]);
    }
  }
};

template <int kP>
inline __m256 Lane(__m256 x) {
  return _mm256_permute_ps(x, kP * 0x55);
}

// Along v (halves of register pairs): the pair (lo = j 0|1, hi = j 2|3).
struct AlongV {
  __m256 lo[4], hi[4];  // lo[j']: a(0, j') | a(1, j'); hi[j']: a(2, j') | a(3, j')
  explicit AlongV(const float* a) {
    for (int jp = 0; jp < 4; ++jp) {
      lo[jp] = _mm256_setr_m128(_mm_set1_ps(a[jp]), _mm_set1_ps(a[4 + jp]));
      hi[jp] = _mm256_setr_m128(_mm_set1_ps(a[8 + jp]), _mm_set1_ps(a[12 + jp]));
    }
  }
};

void ApplyAvx2(const float* mf, const float* df, const float* cd, float cv, float cw,
               const float* x, int ld, int count, double* y) {
  const AlongW mw(mf), dw(df);
  const AlongV mv(mf), dv(df);
  const __m256 vcv = _mm256_set1_ps(cv), vcw = _mm256_set1_ps(cw);
  for (int b = 0; b < count; ++b) {
    const float* xe = x + static_cast<int64_t>(b) * ld;
    __m256 a[8], bb[8];
    for (int r = 0; r < 8; ++r) {
      const __m256 v = _mm256_loadu_ps(xe + 8 * r);
      const __m256 l0 = Lane<0>(v), l1 = Lane<1>(v), l2 = Lane<2>(v), l3 = Lane<3>(v);
      a[r] = _mm256_fmadd_ps(mw.col[3], l3,
                             _mm256_fmadd_ps(mw.col[2], l2,
                                             _mm256_fmadd_ps(mw.col[1], l1,
                                                             _mm256_mul_ps(mw.col[0], l0))));
      bb[r] = _mm256_fmadd_ps(dw.col[3], l3,
                              _mm256_fmadd_ps(dw.col[2], l2,
                                              _mm256_fmadd_ps(dw.col[1], l1,
                                                              _mm256_mul_ps(dw.col[0], l0))));
    }
    __m256 c[8], g[8];
    for (int i = 0; i < 4; ++i) {
      const __m256 a0 = a[2 * i], a1 = a[2 * i + 1], b0 = bb[2 * i], b1 = bb[2 * i + 1];
      const __m256 aj[4] = {_mm256_permute2f128_ps(a0, a0, 0x00),
                            _mm256_permute2f128_ps(a0, a0, 0x11),
                            _mm256_permute2f128_ps(a1, a1, 0x00),
                            _mm256_permute2f128_ps(a1, a1, 0x11)};
      const __m256 bj[4] = {_mm256_permute2f128_ps(b0, b0, 0x00),
                            _mm256_permute2f128_ps(b0, b0, 0x11),
                            _mm256_permute2f128_ps(b1, b1, 0x00),
                            _mm256_permute2f128_ps(b1, b1, 0x11)};
      __m256 clo = _mm256_mul_ps(mv.lo[0], aj[0]), chi = _mm256_mul_ps(mv.hi[0], aj[0]);
      __m256 elo = _mm256_mul_ps(dv.lo[0], aj[0]), ehi = _mm256_mul_ps(dv.hi[0], aj[0]);
      __m256 flo = _mm256_mul_ps(mv.lo[0], bj[0]), fhi = _mm256_mul_ps(mv.hi[0], bj[0]);
      for (int jp = 1; jp < 4; ++jp) {
        clo = _mm256_fmadd_ps(mv.lo[jp], aj[jp], clo);
        chi = _mm256_fmadd_ps(mv.hi[jp], aj[jp], chi);
        elo = _mm256_fmadd_ps(dv.lo[jp], aj[jp], elo);
        ehi = _mm256_fmadd_ps(dv.hi[jp], aj[jp], ehi);
        flo = _mm256_fmadd_ps(mv.lo[jp], bj[jp], flo);
        fhi = _mm256_fmadd_ps(mv.hi[jp], bj[jp], fhi);
      }
      c[2 * i] = clo;
      c[2 * i + 1] = chi;
      g[2 * i] = _mm256_fmadd_ps(vcw, flo, _mm256_mul_ps(vcv, elo));
      g[2 * i + 1] = _mm256_fmadd_ps(vcw, fhi, _mm256_mul_ps(vcv, ehi));
    }
    double* ye = y + static_cast<int64_t>(b) * ld;
    for (int h = 0; h < 2; ++h) {
      for (int i = 0; i < 4; ++i) {
        __m256 acc = _mm256_mul_ps(_mm256_set1_ps(cd[4 * i]), c[h]);
        acc = _mm256_fmadd_ps(_mm256_set1_ps(mf[4 * i]), g[h], acc);
        for (int ip = 1; ip < 4; ++ip) {
          acc = _mm256_fmadd_ps(_mm256_set1_ps(cd[4 * i + ip]), c[2 * ip + h], acc);
          acc = _mm256_fmadd_ps(_mm256_set1_ps(mf[4 * i + ip]), g[2 * ip + h], acc);
        }
        double* o = ye + 8 * (2 * i + h);
        _mm256_storeu_pd(o, _mm256_cvtps_pd(_mm256_castps256_ps128(acc)));
        _mm256_storeu_pd(o + 4, _mm256_cvtps_pd(_mm256_extractf128_ps(acc, 1)));
      }
    }
  }
}
#endif

// The same steps one value at a time (builds without AVX2).
void ApplyScalar(const float* mf, const float* df, const float* cd, float cv, float cw,
                 const float* x, int ld, int count, double* y) {
  auto along = [](int stride, const float* mat, const float* in, float* out) {
    for (int m = 0; m < kN; ++m) {
      const int idx = (m / stride) % 4, base = m - idx * stride;
      float s = 0;
      for (int p = 0; p < 4; ++p) s += mat[4 * idx + p] * in[base + p * stride];
      out[m] = s;
    }
  };
  for (int b = 0; b < count; ++b) {
    const float* xe = x + static_cast<int64_t>(b) * ld;
    float a[kN], bb[kN], c[kN], e[kN], f[kN], g[kN], y1[kN], y2[kN];
    along(1, mf, xe, a);
    along(1, df, xe, bb);
    along(4, mf, a, c);
    along(4, df, a, e);
    along(4, mf, bb, f);
    for (int m = 0; m < kN; ++m) g[m] = cv * e[m] + cw * f[m];
    along(16, cd, c, y1);
    along(16, mf, g, y2);
    for (int m = 0; m < kN; ++m) y[static_cast<int64_t>(b) * ld + m] = y1[m] + y2[m];
  }
}

}  // namespace

void KroneckerStiffness::Apply(int axis, const float* x, int ld, int count, double* y) const {
#ifdef DYNSOLID_KRON_AVX2
  ApplyAvx2(mf_.data(), df_.data(), cd_[axis].data(), cvw_[axis][0], cvw_[axis][1], x, ld,
            count, y);
#else
  ApplyPortable(axis, x, ld, count, y);
#endif
}

void KroneckerStiffness::ApplyPortable(int axis, const float* x, int ld, int count,
                                       double* y) const {
  ApplyScalar(mf_.data(), df_.data(), cd_[axis].data(), cvw_[axis][0], cvw_[axis][1], x, ld,
              count, y);
}

}  // namespace dynsolid::models
