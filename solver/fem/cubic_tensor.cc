#include "solver/fem/cubic_tensor.h"

#include "solver/fem/basis.h"

namespace dynsolid::fem {
namespace {

using Tensor = double[64];  // [16 i + 4 j + k] or, once passed, the points'

// out[16 i + 4 j + c] = sum_k m[c][k] in[16 i + 4 j + k]: along w.
inline void PassW(const std::array<std::array<double, 4>, 4>& m, const double* in, double* out) {
  for (int ij = 0; ij < 16; ++ij) {
    const double* x = in + 4 * ij;
    double* y = out + 4 * ij;
    for (int c = 0; c < 4; ++c) y[c] = m[c][0] * x[0] + m[c][1] * x[1] + m[c][2] * x[2] + m[c][3] * x[3];
  }
}

// out[16 i + 4 b + c] = sum_j m[b][j] in[16 i + 4 j + c]: along v, four
// points c at a time.
inline void PassV(const std::array<std::array<double, 4>, 4>& m, const double* in, double* out) {
  for (int i = 0; i < 4; ++i) {
    const double* x = in + 16 * i;
    double* y = out + 16 * i;
    for (int b = 0; b < 4; ++b) {
      for (int c = 0; c < 4; ++c) {
        y[4 * b + c] = m[b][0] * x[c] + m[b][1] * x[4 + c] + m[b][2] * x[8 + c] + m[b][3] * x[12 + c];
      }
    }
  }
}

// out[16 a + r] = sum_i m[a][i] in[16 i + r]: along u, sixteen points r at
// a time.
inline void PassU(const std::array<std::array<double, 4>, 4>& m, const double* in, double* out) {
  for (int a = 0; a < 4; ++a) {
    for (int r = 0; r < 16; ++r) {
      out[16 * a + r] = m[a][0] * in[r] + m[a][1] * in[16 + r] + m[a][2] * in[32 + r] + m[a][3] * in[48 + r];
    }
  }
}

}  // namespace

bool CubicTensorProducts::Applies(const KindTable& table) {
  return table.kind == ElementKind::kCubic && table.nodes == 64 && table.points == 64;
}

CubicTensorProducts::CubicTensorProducts(const KindTable& table) {
  // The 1D points are the u coordinates of points 16 a (b = c = 0).
  for (int a = 0; a < 4; ++a) {
    const double t = table.uvw[16 * a].x();
    a_[a] = CubicBSpline(t);
    d_[a] = CubicBSplineDerivative(t);
  }
}

void CubicTensorProducts::Values(const double* x, int ld_x, int cols, double* out,
                                 int ld_out) const {
  Tensor t1, t2;
  for (int col = 0; col < cols; ++col) {
    PassW(a_, x + static_cast<int64_t>(col) * ld_x, t1);
    PassV(a_, t1, t2);
    PassU(a_, t2, out + static_cast<int64_t>(col) * ld_out);
  }
}

void CubicTensorProducts::Derivatives(const double* x, int ld_x, int cols, double* out_u,
                                      double* out_v, double* out_w, int ld_out,
                                      double* out_values) const {
  Tensor w0, w1, v00, v10, v01;
  for (int col = 0; col < cols; ++col) {
    const double* in = x + static_cast<int64_t>(col) * ld_x;
    const int64_t o = static_cast<int64_t>(col) * ld_out;
    PassW(a_, in, w0);   // A along w
    PassW(d_, in, w1);   // A' along w
    PassV(a_, w0, v00);  // A A
    PassV(d_, w0, v10);  // A' along v, A along w
    PassV(a_, w1, v01);  // A along v, A' along w
    PassU(d_, v00, out_u + o);
    PassU(a_, v10, out_v + o);
    PassU(a_, v01, out_w + o);
    if (out_values != nullptr) PassU(a_, v00, out_values + o);
  }
}

void CubicTensorProducts::Jacobians(const NodeMatrixX3& x, std::vector<double>& j) const {
  double columns[3 * 64];  // x's coordinates, column major
  for (int m = 0; m < 64; ++m) {
    for (int r = 0; r < 3; ++r) columns[64 * r + m] = x(m, r);
  }
  j.resize(9 * 64);
  // Column r's derivative along u_c lands at j[(3 r + c) 64]: ld_out 192
  // puts column r at 192 r = (3 r) 64.
  Derivatives(columns, 64, 3, j.data(), j.data() + 64, j.data() + 128, 192);
}

}  // namespace dynsolid::fem
