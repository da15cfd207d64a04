#include "solver/models/cubic_quadrature.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include <Eigen/Dense>

#include "solver/fem/basis.h"

namespace dynsolid::models {
namespace {

constexpr int L = kQuadratureLanes;
// The three components of a chunk's elements side by side: lane l + L a
// holds element l's component a, so every contraction runs over 3 L lanes.
constexpr int W = 3 * L;

// One 1D contraction of a 4 x 4 x 4 field (index 16 i + 4 j + k, a row of L
// lanes each) along the axis of stride kStride: out[.., q, ..] = sum_n
// M[q][n] in[.., n, ..], or with kTranspose sum_n M[n][q] in[.., n, ..];
// kAdd adds into out instead of overwriting it.
template <int kStride, bool kTranspose, bool kAdd, typename S>
inline void Contract(const S (*__restrict in)[W], S (*__restrict out)[W], const S (&m)[4][4]) {
  S c[4][4];
  for (int q = 0; q < 4; ++q)
    for (int n = 0; n < 4; ++n) c[q][n] = kTranspose ? m[n][q] : m[q][n];
  for (int o = 0; o < 64; ++o) {
    if ((o / kStride) % 4 != 0) continue;  // o: the line's first entry
    const S* __restrict i0 = in[o];
    const S* __restrict i1 = in[o + kStride];
    const S* __restrict i2 = in[o + 2 * kStride];
    const S* __restrict i3 = in[o + 3 * kStride];
    S* __restrict o0 = out[o];
    S* __restrict o1 = out[o + kStride];
    S* __restrict o2 = out[o + 2 * kStride];
    S* __restrict o3 = out[o + 3 * kStride];
    for (int l = 0; l < W; ++l) {
      const S a0 = i0[l], a1 = i1[l], a2 = i2[l], a3 = i3[l];
      const S y0 = c[0][0] * a0 + c[0][1] * a1 + c[0][2] * a2 + c[0][3] * a3;
      const S y1 = c[1][0] * a0 + c[1][1] * a1 + c[1][2] * a2 + c[1][3] * a3;
      const S y2 = c[2][0] * a0 + c[2][1] * a1 + c[2][2] * a2 + c[2][3] * a3;
      const S y3 = c[3][0] * a0 + c[3][1] * a1 + c[3][2] * a2 + c[3][3] * a3;
      if constexpr (kAdd) {
        o0[l] += y0, o1[l] += y1, o2[l] += y2, o3[l] += y3;
      } else {
        o0[l] = y0, o1[l] = y1, o2[l] = y2, o3[l] = y3;
      }
    }
  }
}

template <typename S>
struct Basis1d {
  S b[4][4], d[4][4];
};
inline Basis1d<double> BasisIn(const CubicQuadratureBasis& basis, double) {
  Basis1d<double> o;
  std::copy(&basis.b[0][0], &basis.b[0][0] + 16, &o.b[0][0]);
  std::copy(&basis.db[0][0], &basis.db[0][0] + 16, &o.d[0][0]);
  return o;
}
inline Basis1d<float> BasisIn(const CubicQuadratureBasis& basis, float) {
  Basis1d<float> o;
  std::copy(&basis.bf[0][0], &basis.bf[0][0] + 16, &o.b[0][0]);
  std::copy(&basis.dbf[0][0], &basis.dbf[0][0] + 16, &o.d[0][0]);
  return o;
}

}  // namespace

bool CubicQuadratureBasis::Make(const fem::KindTable& table, CubicQuadratureBasis& out) {
  if (table.kind != fem::ElementKind::kCubic || table.points != 64 || table.nodes != 64) {
    return false;
  }
  // The 1D points: u of points 0, 16, 32, 48.
  for (int q = 0; q < 4; ++q) {
    const double t = table.uvw[16 * q].x();
    const std::array<double, 4> b = fem::CubicBSpline(t), db = fem::CubicBSplineDerivative(t);
    for (int i = 0; i < 4; ++i) {
      out.b[q][i] = b[i];
      out.db[q][i] = db[i];
      out.bf[q][i] = static_cast<float>(b[i]);
      out.dbf[q][i] = static_cast<float>(db[i]);
    }
  }
  // The tensor products against the table.
  for (int q = 0; q < 64; ++q) {
    const int qi = q / 16, qj = (q / 4) % 4, qk = q % 4;
    const double* dn = table.dN(q);
    for (int m = 0; m < 64; ++m) {
      const int i = m / 16, j = (m / 4) % 4, k = m % 4;
      const double e[3] = {out.db[qi][i] * out.b[qj][j] * out.b[qk][k],
                           out.b[qi][i] * out.db[qj][j] * out.b[qk][k],
                           out.b[qi][i] * out.b[qj][j] * out.db[qk][k]};
      for (int c = 0; c < 3; ++c) {
        if (std::abs(e[c] - dn[3 * m + c]) > 1e-12) return false;
      }
    }
  }
  return true;
}

void SetCubicQuadratureFactors(const fem::KindTable& table, const fem::NodeMatrixX3& rest,
                               const std::vector<MaterialPoint>& material, double scale,
                               double* chunk, int lane) {
  // J(c, k) = d x_c / d u_k = sum_i rest(i, c) dN_i / du_k.
  thread_local std::vector<double> js;
  fem::RestJacobians(table, rest, js);
  for (int q = 0; q < table.points; ++q) {
    const Eigen::Matrix3d j = fem::JacobianAt(js, table.points, q);
    const double det = j.determinant();
    // As the dense path: a point of an inverted element adds nothing.
    const double dv = std::max(det, 0.0) * table.weight[q] * scale;
    const Eigen::Matrix3d jinv = dv > 0 ? Eigen::Matrix3d(j.inverse()) : Eigen::Matrix3d::Zero();
    double* f = chunk + static_cast<int64_t>(q) * kFactorsPerPoint * L;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) f[(3 * r + c) * L + lane] = jinv(r, c);
    f[9 * L + lane] = dv * material[q].lame_lambda();
    f[10 * L + lane] = dv * material[q].lame_mu();
  }
}

// The point's step for the local-frame model: each component a on its own,
// s_c = k_ac p_c with k_aa = dV (lambda + 2 mu), k_ac = dV mu.
template <typename S>
inline void LocalFramePoint(const S (&j)[9], S lam, S mu, S (&r)[3][3]) {
  const S stiff = lam + mu + mu;
  for (int a = 0; a < 3; ++a) {
    S p[3];
    for (int c = 0; c < 3; ++c) {
      p[c] = (r[a][0] * j[c] + r[a][1] * j[3 + c] + r[a][2] * j[6 + c]) * (c == a ? stiff : mu);
    }
    for (int k = 0; k < 3; ++k) r[a][k] = j[3 * k] * p[0] + j[3 * k + 1] * p[1] + j[3 * k + 2] * p[2];
  }
}

// The point's step for isotropic linear elasticity (the corotational
// model): H = r Jinv (H_ac = d u_a / d x_c), sigma = dV lambda tr(H) I +
// dV mu (H + H^T), t = sigma Jinv^T.
template <typename S>
inline void IsotropicPoint(const S (&j)[9], S lam, S mu, S (&r)[3][3]) {
  S h[3][3];
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) h[a][c] = r[a][0] * j[c] + r[a][1] * j[3 + c] + r[a][2] * j[6 + c];
  const S tr = lam * (h[0][0] + h[1][1] + h[2][2]);
  S sg[3][3];
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) sg[a][c] = mu * (h[a][c] + h[c][a]) + (a == c ? tr : S(0));
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < 3; ++k)
      r[a][k] = sg[a][0] * j[3 * k] + sg[a][1] * j[3 * k + 1] + sg[a][2] * j[3 * k + 2];
}

template <CubicPointLaw kLaw, typename S, typename T>
void ApplyCubicQuadrature(const CubicQuadratureBasis& basis, const S* factors, int count,
                          const T* const x[3], int64_t ld, int node_stride, double* const y[3]) {
  const Basis1d<S> bs = BasisIn(basis, S(0));
  const auto& B = bs.b;
  const auto& D = bs.d;
  // Six buffers of 64 x W, reused stage by stage (36 KB in float).
  alignas(64) S f[64][W], a1[64][W], a2[64][W], c3[64][W], c4[64][W], c5[64][W];
  for (int a = 0; a < 3; ++a) {
    for (int l = 0; l < L; ++l) {
      for (int m = 0; m < 64; ++m) {
        f[m][L * a + l] = l < count ? static_cast<S>(x[a][l * ld + m * node_stride]) : S(0);
      }
    }
  }
  // Reference gradients at the points: along w (stride 1), v (4), u (16):
  // d/du into f, d/dv into a1, d/dw into a2.
  Contract<1, false, false>(f, a1, B);
  Contract<1, false, false>(f, a2, D);
  Contract<4, false, false>(a1, c3, B);
  Contract<4, false, false>(a1, c4, D);
  Contract<4, false, false>(a2, c5, B);
  Contract<16, false, false>(c3, f, D);
  Contract<16, false, false>(c4, a1, B);
  Contract<16, false, false>(c5, a2, B);
  // At each point: to physical gradients, the material's response, and
  // back to the reference gradients' weights.
  for (int q = 0; q < 64; ++q) {
    const S* fq = factors + static_cast<int64_t>(q) * kFactorsPerPoint * L;
    S* __restrict ru = f[q];
    S* __restrict rv = a1[q];
    S* __restrict rw = a2[q];
    for (int l = 0; l < L; ++l) {
      S j[9];
      for (int k = 0; k < 9; ++k) j[k] = fq[k * L + l];
      const S lam = fq[9 * L + l], mu = fq[10 * L + l];
      S r[3][3];
      for (int a = 0; a < 3; ++a) {
        r[a][0] = ru[L * a + l];
        r[a][1] = rv[L * a + l];
        r[a][2] = rw[L * a + l];
      }
      if constexpr (kLaw == CubicPointLaw::kLocalFrame) {
        LocalFramePoint(j, lam, mu, r);
      } else {
        IsotropicPoint(j, lam, mu, r);
      }
      for (int a = 0; a < 3; ++a) {
        ru[L * a + l] = r[a][0];
        rv[L * a + l] = r[a][1];
        rw[L * a + l] = r[a][2];
      }
    }
  }
  // The transposes in reverse order.
  Contract<16, true, false>(f, c3, D);
  Contract<16, true, false>(a1, c4, B);
  Contract<16, true, false>(a2, c5, B);
  Contract<4, true, false>(c3, a1, B);
  Contract<4, true, true>(c4, a1, D);
  Contract<4, true, false>(c5, a2, B);
  Contract<1, true, false>(a1, f, B);
  Contract<1, true, true>(a2, f, D);
  for (int a = 0; a < 3; ++a) {
    for (int l = 0; l < count; ++l) {
      for (int m = 0; m < 64; ++m) {
        y[a][l * ld + m * node_stride] = static_cast<double>(f[m][L * a + l]);
      }
    }
  }
}

std::vector<uint8_t> CubicQuadratureElements::Choose(const ElementLayout& layout,
                                                     int32_t group_size) {
  const ElementBlock& cubic = layout.blocks[0];
  if (group_size <= 0 || cubic.size() == 0 || !CubicQuadratureBasis::Make(layout.tables[0], basis_)) {
    return std::vector<uint8_t>(cubic.groups.size(), 0);
  }
  return SmallGroups(cubic, group_size);
}

void CubicQuadratureElements::Build(const ElementLayout& layout, const ElementSchedule& schedule,
                                    double scale) {
  const ElementBlock& cubic = layout.blocks[0];
  // The pooled batches run last among the cubic ones.
  first_ = static_cast<int32_t>(schedule.order[0].size());
  for (const ElementBatch& batch : schedule.batches) {
    if (batch.group == kPooled && batch.kind == 0) first_ = std::min(first_, batch.first);
  }
  size_ = static_cast<int64_t>(schedule.order[0].size()) - first_;
  const int64_t chunks = (size_ + L - 1) / L;
  factors_.assign(chunks * kChunkValues, 0.0);
  // Elements of one group have the same factors (shape up to translation,
  // material): made once per group (in lane 0 of a scratch chunk, kept
  // contiguous), then written chunk by chunk, all lanes of a factor
  // together (one element's lane at a time strides a cache line a value).
  constexpr int64_t kValues = int64_t{64} * kFactorsPerPoint;
  std::vector<int32_t> slot(cubic.groups.size(), -1);
  std::vector<double> made;  // slot s: made[s kValues ..]
  std::vector<double> scratch(kChunkValues);
  std::vector<int32_t> source(size_);
  for (int64_t k = 0; k < size_; ++k) {
    const int32_t gi = cubic.group[schedule.order[0][first_ + k]];
    if (slot[gi] < 0) {
      const ElementGroup& grp = cubic.groups[gi];
      for (int64_t r = 0; r < kValues; ++r) scratch[r * L] = 0.0;
      SetCubicQuadratureFactors(layout.tables[0], grp.rest, layout.materials[grp.material], scale,
                                scratch.data(), 0);
      slot[gi] = static_cast<int32_t>(made.size() / kValues);
      for (int64_t r = 0; r < kValues; ++r) made.push_back(scratch[r * L]);
    }
    source[k] = slot[gi];
  }
  for (int64_t c = 0; c < chunks; ++c) {
    double* chunk = factors_.data() + c * kChunkValues;
    const double* from[L] = {};
    for (int lane = 0; lane < L && c * L + lane < size_; ++lane) {
      from[lane] = made.data() + static_cast<int64_t>(source[c * L + lane]) * kValues;
    }
    for (int64_t r = 0; r < kValues; ++r) {
      for (int lane = 0; lane < L; ++lane) {
        if (from[lane] != nullptr) chunk[r * L + lane] = from[lane][r];
      }
    }
  }
  if (!factors_f_.empty()) SetFloat(true);
}

void CubicQuadratureElements::SetFloat(bool on) {
  if (on) {
    factors_f_.assign(factors_.begin(), factors_.end());
  } else {
    factors_f_ = {};
  }
}

Eigen::MatrixXd CubicQuadratureElements::Matrix(CubicPointLaw law, const ElementLayout& layout,
                                                int32_t group, double scale, int axis) const {
  const ElementGroup& grp = layout.blocks[0].groups[group];
  // The group's factors in every lane.
  std::vector<double> chunk(kChunkValues);
  for (int lane = 0; lane < L; ++lane) {
    SetCubicQuadratureFactors(layout.tables[0], grp.rest, layout.materials[grp.material], scale,
                              chunk.data(), lane);
  }
  const bool iso = law == CubicPointLaw::kIsotropic;
  const int n = iso ? 192 : 64;
  Eigen::MatrixXd x = Eigen::MatrixXd::Identity(n, n), k(n, n);
  // Columns as the law reads them: node-major (stride 3) for kIsotropic,
  // component `axis` alone for kLocalFrame.
  std::vector<double> zeros(static_cast<size_t>(n) * L, 0.0), sink(static_cast<size_t>(n) * L);
  for (int c = 0; c < n; c += L) {
    const int count = std::min(L, n - c);
    if (iso) {
      const double* xs[3] = {x.data() + int64_t{c} * n, x.data() + int64_t{c} * n + 1,
                             x.data() + int64_t{c} * n + 2};
      double* ys[3] = {k.data() + int64_t{c} * n, k.data() + int64_t{c} * n + 1,
                       k.data() + int64_t{c} * n + 2};
      ApplyCubicQuadrature<CubicPointLaw::kIsotropic, double, double>(basis_, chunk.data(), count,
                                                                      xs, n, 3, ys);
    } else {
      const double* xs[3] = {zeros.data(), zeros.data(), zeros.data()};
      double* ys[3] = {sink.data(), sink.data(), sink.data()};
      xs[axis] = x.data() + int64_t{c} * n;
      ys[axis] = k.data() + int64_t{c} * n;
      ApplyCubicQuadrature<CubicPointLaw::kLocalFrame, double, double>(basis_, chunk.data(), count,
                                                                       xs, n, 1, ys);
    }
  }
  return 0.5 * (k + k.transpose());
}

template <CubicPointLaw kLaw, typename S, typename T>
void CubicQuadratureElements::Apply(int32_t first, int32_t count, const T* const x[3], int64_t ld,
                                    int node_stride, double* const y[3]) const {
  // Pooled batches start on a chunk.
  const int64_t at = first - first_;
  for (int32_t c = 0; c < count; c += L) {
    const T* xc[3] = {x[0] + c * ld, x[1] + c * ld, x[2] + c * ld};
    double* yc[3] = {y[0] + c * ld, y[1] + c * ld, y[2] + c * ld};
    const int64_t chunk = (at + c) / L * kChunkValues;
    const int n = std::min<int32_t>(L, count - c);
    if constexpr (std::is_same_v<S, float>) {
      ApplyCubicQuadrature<kLaw, S, T>(basis_, factors_f_.data() + chunk, n, xc, ld, node_stride,
                                       yc);
    } else {
      ApplyCubicQuadrature<kLaw, S, T>(basis_, factors_.data() + chunk, n, xc, ld, node_stride,
                                       yc);
    }
  }
}

#define DYNSOLID_INSTANTIATE(LAW, S, T)                                                       \
  template void ApplyCubicQuadrature<CubicPointLaw::LAW, S, T>(                                \
      const CubicQuadratureBasis&, const S*, int, const T* const[3], int64_t, int, double* const[3]); \
  template void CubicQuadratureElements::Apply<CubicPointLaw::LAW, S, T>(                      \
      int32_t, int32_t, const T* const[3], int64_t, int, double* const[3]) const;
DYNSOLID_INSTANTIATE(kLocalFrame, double, double)
DYNSOLID_INSTANTIATE(kLocalFrame, float, float)
DYNSOLID_INSTANTIATE(kIsotropic, double, double)
DYNSOLID_INSTANTIATE(kIsotropic, float, double)
#undef DYNSOLID_INSTANTIATE

}  // namespace dynsolid::models
