#include "solver/models/local_frame.h"

#include <chrono>
#include <cmath>
#include <type_traits>

#include "solver/fem/quadrature.h"
#include "solver/models/rotation.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>

#include "solver/models/simd_rows.h"
#define DYNSOLID_LF_AVX2 1
#endif

namespace dynsolid::models {
namespace {

constexpr int32_t kBatch = 64;
// A batch's node rows, gathered from the big arrays once per batch: row j
// (global node nodes[j]) holds d in doubles 0-2 and delta in 4-6 of a
// 64-byte line (kLocalStride), so an element's loads are aligned and hit
// L1. The sums R_e K dhat go into rows of kSumStride doubles (x, y, z, 0).
constexpr int kLocalStride = 8;
constexpr int kSumStride = 4;

// The frame's Newton iteration stops after a step below 1e-5 rad (an error
// of about 1e-10 rad left; rotation.h). The frame only rotates the
// rotation-blind measure delta, so a frame error e moves the force by e of
// itself: 1e-10 against CG's 1e-4. From a one-step-old warm start the
// Newton iteration lands on the polar rotation in two steps; the exit
// saves the third evaluation, which would only confirm it (the frame is
// the same to the bit: rotation_test).
constexpr double kFrameNewtonExit = 1e-5;

}  // namespace

namespace {

// A group's three matrices K_x, K_y, K_z (local_frame.h), integrated.
std::array<Eigen::MatrixXd, 3> IntegrateGroup(const fem::KindTable& table, const ElementGroup& grp,
                                              const std::vector<MaterialPoint>& material) {
  const int n = table.nodes;
  fem::NodeMatrixX3 g;
  // K_x = sum_q dV [(l + 2m) gx gx^T + m gy gy^T + m gz gz^T] = B_x B_x^T
  // with B_x's columns sqrt(dV (l + 2m)) gx, sqrt(dV m) gy, sqrt(dV m) gz.
  std::array<Eigen::MatrixXd, 3> b;
  for (auto& m : b) m.resize(n, 3 * table.points);
  for (int q = 0; q < table.points; ++q) {
    const double det = fem::PhysicalGradients(table.dN(q), grp.rest, n, g);
    const double dv = std::max(det, 0.0) * table.weight[q] * kStiffnessFactor;
    const double lam = material[q].lame_lambda(), mu = material[q].lame_mu();
    for (int axis = 0; axis < 3; ++axis) {
      for (int c = 0; c < 3; ++c) {
        const double coef = std::sqrt(dv * (c == axis ? lam + 2 * mu : mu));
        b[axis].col(3 * q + c) = coef * g.col(c);
      }
    }
  }
  return {b[0] * b[0].transpose(), b[1] * b[1].transpose(), b[2] * b[2].transpose()};
}

}  // namespace

LocalFrameModel::LocalFrameModel(const ElementLayout& layout, DeformationMeasure measure,
                                 int32_t num_nodes, WorkerPool& pool,
                                 const LocalFrameModel* previous, bool float_products,
                                 int32_t quadrature_group_size)
    : layout_(layout),
      pool_(&pool),
      measure_(std::move(measure)),
      num_nodes_(num_nodes),
      float_products_(float_products) {
  if (previous != nullptr && previous->float_products_ != float_products) previous = nullptr;
  // Small cubic groups go to the quadrature points.
  const ElementBlock& cubic = layout.blocks[0];
  pooled_[0] = quadrature_.Choose(layout, quadrature_group_size);
  for (int kind = 1; kind < fem::kElementKinds; ++kind) {
    pooled_[kind] = SmallGroups(layout.blocks[kind], quadrature_group_size);
  }
  // The cubic table's rule is a tensor Gauss rule of n1 points a side.
  std::optional<KroneckerBasis> kron_basis;
  if (float_products && cubic.size() > 0) {
    const int n1 = static_cast<int>(std::lround(std::cbrt(layout.tables[0].points)));
    const fem::Rule1d rule = fem::GaussLegendre(n1);
    kron_basis = KroneckerBasis::Make(rule.points, rule.weights);
  }
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& block = layout.blocks[kind];
    const fem::KindTable& table = layout.tables[kind];
    const std::vector<int32_t> reuse = previous != nullptr
                                           ? MatchStiffnessGroups(layout, previous->layout_, kind)
                                           : std::vector<int32_t>(block.groups.size(), -1);
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      if (kind == 0 && pooled_[0][gi]) {
        // Applied at the quadrature points: no matrices.
        if (float_products) {
          packed_f_[kind].emplace_back();
          kron_.emplace_back();
        } else {
          packed_[kind].emplace_back();
        }
        continue;
      }
      if (reuse[gi] >= 0 && !(kind == 0 && previous->pooled_[0][reuse[gi]])) {
        if (float_products) {
          packed_f_[kind].push_back(previous->packed_f_[kind][reuse[gi]]);
          if (kind == 0) kron_.push_back(previous->kron_[reuse[gi]]);
        } else {
          packed_[kind].push_back(previous->packed_[kind][reuse[gi]]);
        }
        continue;
      }
      ++integrated_groups_;
      const ElementGroup& grp = block.groups[gi];
      const std::array<Eigen::MatrixXd, 3> dense =
          IntegrateGroup(table, grp, layout.materials[grp.material]);
      const std::array<PackedMatrix, 3> k = {PackedMatrix(dense[0]), PackedMatrix(dense[1]),
                                             PackedMatrix(dense[2])};
      if (kind == 0 && kron_basis) kron_.push_back(KroneckerStiffness::Fit(*kron_basis, dense));
      if (float_products) {
        packed_f_[kind].push_back({PackedMatrixF(k[0]), PackedMatrixF(k[1]), PackedMatrixF(k[2])});
      } else {
        packed_[kind].push_back(k);
      }
    }
    if (kind > 0) {
      // Pooled small groups: their matrices for plain products.
      const int n = block.nodes;
      small_[kind].resize(block.groups.size());
      if (float_products) small_f_[kind].resize(block.groups.size());
      for (size_t gi = 0; gi < block.groups.size(); ++gi) {
        if (!pooled_[kind][gi]) continue;
        std::vector<double>& k = small_[kind][gi];
        k.resize(3 * static_cast<size_t>(n) * n);
        for (int axis = 0; axis < 3; ++axis) {
          const Eigen::MatrixXd m = K(kind, static_cast<int32_t>(gi), axis);
          for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) k[(axis * n + i) * n + j] = m(i, j);
        }
        if (float_products) small_f_[kind][gi].assign(k.begin(), k.end());
      }
    }
    frames_[kind].assign(block.size(), Eigen::Quaterniond::Identity());
    centre_gradient_[kind].resize(block.groups.size());
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      centre_gradient_[kind][gi] = block.groups[gi].centre_gradient;  // to column-major
    }
  }
  work_.resize(kForceParts);
  schedule_ = ScheduleElements(layout, kBatch, kForceParts, num_nodes_, &pooled_);
  IndexBatchNodes(layout, schedule_);
  quadrature_.Build(layout, schedule_, kStiffnessFactor);
  quadrature_.SetFloat(float_products);
  for (Workspace& w : work_) {
    w.g.setZero(num_nodes_, 3);
    // Room for the largest batch's rows, plus a line for the alignment.
    w.local.assign(kLocalStride * (static_cast<size_t>(schedule_.max_batch_nodes) + 1), 0.0);
    w.sums.assign(kSumStride * static_cast<size_t>(schedule_.max_batch_nodes) + kLocalStride, 0.0);
    part_buffers_.push_back(&w.g);
    for (Eigen::MatrixXd* m : {&w.dx, &w.dy, &w.dz, &w.yx, &w.yy, &w.yz}) {
      m->setZero(fem::kCubicNodes, kBatch);
    }
    if (float_products) {
      for (Eigen::MatrixXf* m : {&w.fx, &w.fy, &w.fz}) m->setZero(fem::kCubicNodes, kBatch);
    }
  }
  delta_.setZero(num_nodes_, 3);
  y_.setZero(num_nodes_, 3);
}

Eigen::MatrixXd LocalFrameModel::K(int kind, int32_t group, int axis) const {
  if (kind == 0 && pooled_[0][group]) {
    return quadrature_.Matrix(CubicPointLaw::kLocalFrame, layout_, group, kStiffnessFactor, axis);
  }
  return float_products_ ? packed_f_[kind][group][axis].Unpack()
                         : packed_[kind][group][axis].Unpack();
}

InternalForceModel::Frames LocalFrameModel::frames() const {
  Frames out;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const std::vector<int32_t>& order = schedule_.order[kind];
    out[kind].resize(frames_[kind].size());
    for (size_t k = 0; k < order.size(); ++k) out[kind][order[k]] = frames_[kind][k];
  }
  return out;
}

void LocalFrameModel::set_frames(const Frames& frames) {
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const std::vector<int32_t>& order = schedule_.order[kind];
    for (size_t k = 0; k < order.size(); ++k) frames_[kind][k] = frames[kind][order[k]];
  }
}

void LocalFrameModel::ResetFrames() {
  for (auto& f : frames_) std::fill(f.begin(), f.end(), Eigen::Quaterniond::Identity());
}

namespace {

inline double* AlignedRows(std::vector<double>& store) {
  return reinterpret_cast<double*>((reinterpret_cast<uintptr_t>(store.data()) + 63) &
                                   ~uintptr_t{63});
}

// Row j of `local` = node nodes[j]'s d and delta rows (kLocalStride).
void GatherRows(int m, const int32_t* nodes, const double* d, const double* delta,
                double* local) {
  for (int j = 0; j < m; ++j) {
    double* o = local + kLocalStride * j;
#ifdef DYNSOLID_LF_AVX2
    _mm256_store_pd(o, simd::LoadRow(d, nodes[j]));
    _mm256_store_pd(o + 4, simd::LoadRow(delta, nodes[j]));
#else
    const double* a = d + 3 * static_cast<int64_t>(nodes[j]);
    const double* b = delta + 3 * static_cast<int64_t>(nodes[j]);
    o[0] = a[0], o[1] = a[1], o[2] = a[2], o[3] = 0;
    o[4] = b[0], o[5] = b[1], o[6] = b[2], o[7] = 0;
#endif
  }
}

// g[nodes[j]] += sums row j, for the batch's m nodes.
void ScatterRows(int m, const int32_t* nodes, const double* sums, double* g) {
  for (int j = 0; j < m; ++j) {
    double* o = g + 3 * static_cast<int64_t>(nodes[j]);
    const double* a = sums + kSumStride * j;
#ifdef DYNSOLID_LF_AVX2
    _mm_storeu_pd(o, _mm_add_pd(_mm_loadu_pd(o), _mm_load_pd(a)));
#else
    o[0] += a[0];
    o[1] += a[1];
#endif
    o[2] += a[2];
  }
}

// One element's frame and local deformation: F = sum_i x_i grad_i^T at the
// centre (grad: n x 3 column-major), R_e its rotation (warm started in q),
// and the columns dhat = R_e^T delta_i split by axis into dx, dy, dz. The
// element's node i is row lid[i] of the batch's gathered rows `local`.
// kN > 0 fixes the node count at compile time (cubic 64, linear 8).
template <int kN, typename T>
void LocalDeformation(int n_dyn, const double* local, const uint16_t* lid, const double* grad,
                      Eigen::Quaterniond& q, Eigen::Matrix3d& r, T* dx, T* dy, T* dz) {
  const int n = kN > 0 ? kN : n_dyn;
  constexpr int kRows = (kN > 0) ? kN : Eigen::Dynamic;
  using Vec = Eigen::Matrix<double, kRows, 1, 0, (kN > 0 ? kN : fem::kCubicNodes), 1>;
  using CMap = Eigen::Map<const Eigen::Matrix<double, kRows, 1>>;
  using Map = Eigen::Map<Eigen::Matrix<T, kRows, 1>>;
  Vec px(n), py(n), pz(n), qx(n), qy(n), qz(n);
  for (int i = 0; i < n; ++i) {
    const double* a = local + kLocalStride * lid[i];
    px[i] = a[0];
    py[i] = a[1];
    pz[i] = a[2];
    qx[i] = a[4];
    qy[i] = a[5];
    qz[i] = a[6];
  }
  Eigen::Matrix3d f;
  for (int c = 0; c < 3; ++c) {
    const CMap gc(grad + static_cast<int64_t>(c) * n, n);
    f(0, c) = px.dot(gc);
    f(1, c) = py.dot(gc);
    f(2, c) = pz.dot(gc);
  }
  ExtractRotation(f, q, 8, &r, kFrameNewtonExit);
  Map(dx, n) = (r(0, 0) * qx + r(1, 0) * qy + r(2, 0) * qz).template cast<T>();
  Map(dy, n) = (r(0, 1) * qx + r(1, 1) * qy + r(2, 1) * qz).template cast<T>();
  Map(dz, n) = (r(0, 2) * qx + r(1, 2) * qy + r(2, 2) * qz).template cast<T>();
}

#ifdef DYNSOLID_LF_AVX2
// The same for n a multiple of 4 (cubic 64, linear 8), four nodes at a
// time: the gathered rows are loaded whole (aligned) and transposed in
// registers, and delta's columns kept on the stack for the rotation. F's
// terms are summed per lane over nodes i = 4 t + lane, then the lanes
// added in a fixed order: the bits depend on the element alone.
using simd::RowsToColumns;

inline double Sum4(__m256d v) {
  alignas(32) double a[4];
  _mm256_store_pd(a, v);
  return (a[0] + a[1]) + (a[2] + a[3]);
}

// Four values of a dhat column stored as T (float: rounded here).
inline void StoreColumn(double* out, __m256d v) { _mm256_storeu_pd(out, v); }
inline void StoreColumn(float* out, __m256d v) { _mm_storeu_ps(out, _mm256_cvtpd_ps(v)); }

template <typename T>
void LocalDeformationAvx2(int n, const double* local, const uint16_t* lid, const double* grad,
                          Eigen::Quaterniond& q, Eigen::Matrix3d& r, T* dx, T* dy, T* dz) {
  alignas(32) double cx[fem::kCubicNodes], cy[fem::kCubicNodes], cz[fem::kCubicNodes];
  __m256d f[3][3];
  for (auto& row : f)
    for (auto& v : row) v = _mm256_setzero_pd();
  for (int i = 0; i < n; i += 4) {
    const double* p0 = local + kLocalStride * lid[i];
    const double* p1 = local + kLocalStride * lid[i + 1];
    const double* p2 = local + kLocalStride * lid[i + 2];
    const double* p3 = local + kLocalStride * lid[i + 3];
    __m256d x, y, z;
    RowsToColumns(_mm256_load_pd(p0), _mm256_load_pd(p1), _mm256_load_pd(p2),
                  _mm256_load_pd(p3), x, y, z);
    for (int c = 0; c < 3; ++c) {
      const __m256d g = _mm256_loadu_pd(grad + c * n + i);
      f[0][c] = _mm256_fmadd_pd(x, g, f[0][c]);
      f[1][c] = _mm256_fmadd_pd(y, g, f[1][c]);
      f[2][c] = _mm256_fmadd_pd(z, g, f[2][c]);
    }
    RowsToColumns(_mm256_load_pd(p0 + 4), _mm256_load_pd(p1 + 4), _mm256_load_pd(p2 + 4),
                  _mm256_load_pd(p3 + 4), x, y, z);
    _mm256_store_pd(cx + i, x);
    _mm256_store_pd(cy + i, y);
    _mm256_store_pd(cz + i, z);
  }
  Eigen::Matrix3d fm;
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) fm(a, c) = Sum4(f[a][c]);
  ExtractRotation(fm, q, 8, &r, kFrameNewtonExit);
  // dhat_i = R^T delta_i: column a of the output is R(:, a) . delta_i.
  __m256d rr[3][3];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) rr[a][b] = _mm256_set1_pd(r(b, a));
  T* out[3] = {dx, dy, dz};
  for (int i = 0; i < n; i += 4) {
    const __m256d x = _mm256_load_pd(cx + i), y = _mm256_load_pd(cy + i),
                  z = _mm256_load_pd(cz + i);
    for (int a = 0; a < 3; ++a) {
      const __m256d v =
          _mm256_fmadd_pd(rr[a][2], z, _mm256_fmadd_pd(rr[a][1], y, _mm256_mul_pd(rr[a][0], x)));
      StoreColumn(out[a] + i, v);
    }
  }
}

inline __m256d LoadWide(const double* p) { return _mm256_loadu_pd(p); }
inline __m256d LoadWide(const float* p) { return _mm256_cvtps_pd(_mm_loadu_ps(p)); }

// sums[lid_i] += R (yx_i, yy_i, yz_i), four nodes at a time (aligned rows
// of kSumStride); returns the element's energy 1/2 dhat . y from the same
// loads of y (dhat's columns dx, dy, dz).
template <typename T>
double RotateBackAndAddAvx2(int n, const Eigen::Matrix3d& r, const T* dx, const T* dy,
                            const T* dz, const double* yx, const double* yy, const double* yz,
                            const uint16_t* lid, double* sums) {
  __m256d rr[3][3];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) rr[a][b] = _mm256_set1_pd(r(a, b));
  __m256d energy = _mm256_setzero_pd();
  for (int i = 0; i < n; i += 4) {
    const __m256d ax = _mm256_loadu_pd(yx + i), ay = _mm256_loadu_pd(yy + i),
                  az = _mm256_loadu_pd(yz + i);
    energy = _mm256_fmadd_pd(LoadWide(dx + i), ax, energy);
    energy = _mm256_fmadd_pd(LoadWide(dy + i), ay, energy);
    energy = _mm256_fmadd_pd(LoadWide(dz + i), az, energy);
    __m256d o[3];
    for (int a = 0; a < 3; ++a) {
      o[a] = _mm256_fmadd_pd(rr[a][2], az,
                             _mm256_fmadd_pd(rr[a][1], ay, _mm256_mul_pd(rr[a][0], ax)));
    }
    __m256d row[4];
    simd::ColumnsToRows(o[0], o[1], o[2], row);
    for (int k = 0; k < 4; ++k) {
      double* p = sums + kSumStride * lid[i + k];
      _mm256_store_pd(p, _mm256_add_pd(_mm256_load_pd(p), row[k]));
    }
  }
  return 0.5 * Sum4(energy);
}
#endif

// sums[lid_i] += R_e (yx_i, yy_i, yz_i) for the element's nodes.
template <int kN>
void RotateBackAndAdd(int n_dyn, const Eigen::Matrix3d& r, const double* yx, const double* yy,
                      const double* yz, const uint16_t* lid, double* sums) {
  const int n = kN > 0 ? kN : n_dyn;
  constexpr int kRows = (kN > 0) ? kN : Eigen::Dynamic;
  using Vec = Eigen::Matrix<double, kRows, 1, 0, (kN > 0 ? kN : fem::kCubicNodes), 1>;
  using CMap = Eigen::Map<const Eigen::Matrix<double, kRows, 1>>;
  const CMap ax(yx, n), ay(yy, n), az(yz, n);
  const Vec gx = r(0, 0) * ax + r(0, 1) * ay + r(0, 2) * az;
  const Vec gy = r(1, 0) * ax + r(1, 1) * ay + r(1, 2) * az;
  const Vec gz = r(2, 0) * ax + r(2, 1) * ay + r(2, 2) * az;
  for (int i = 0; i < n; ++i) {
    double* o = sums + kSumStride * lid[i];
    o[0] += gx[i];
    o[1] += gy[i];
    o[2] += gz[i];
  }
}

// The shared matrices' products in precision T: float (PackedMatrixF) or
// double (PackedMatrix).
inline void ApplyK(const PackedMatrix& k, const double* x, int ld, int count, double* y) {
  k.Apply(x, ld, count, y, ld);
}
inline void ApplyK(const PackedMatrixF& k, const float* x, int ld, int count, double* y) {
  k.Apply(x, ld, count, y, ld);
}

}  // namespace

template <typename T, typename KSet>
void LocalFrameModel::RunBatches(int part, const Points& d, const KSet& packed, Workspace& w) {
  std::array<Eigen::Matrix3d, kBatch> rot;
  ClearPartRows(schedule_, part, w.g);
  w.energy = 0;
  double* local = AlignedRows(w.local);
  double* sums = AlignedRows(w.sums);
  const int ld = fem::kCubicNodes;  // leading dimension of the batch columns
  T* cols[3];
  if constexpr (std::is_same_v<T, float>) {
    cols[0] = w.fx.data(), cols[1] = w.fy.data(), cols[2] = w.fz.data();
  } else {
    cols[0] = w.dx.data(), cols[1] = w.dy.data(), cols[2] = w.dz.data();
  }
  for (size_t bi = schedule_.part_start[part]; bi < schedule_.part_start[part + 1]; ++bi) {
    const ElementBatch& batch = schedule_.batches[bi];
    const ElementBlock& block = layout_.blocks[batch.kind];
    const int n = block.nodes;
    const bool pooled = batch.group == kPooled;
    const double* grad = pooled ? nullptr : centre_gradient_[batch.kind][batch.group].data();
    const int32_t* nodes = schedule_.batch_nodes.data() + batch.nodes_begin;
    const uint16_t* lids = schedule_.local_ids.data() + batch.local_begin;
    GatherRows(batch.num_nodes, nodes, d.data(), delta_.data(), local);
    // The rows of the batch two ahead (d and delta to read, the buffer to
    // update) are fetched towards L2 now, so their misses overlap this
    // batch's and the next one's work; the next batch's element frames a
    // share per element.
    if (bi + 2 < schedule_.part_start[part + 1]) {
      const ElementBatch& ahead = schedule_.batches[bi + 2];
      const int32_t* ahead_nodes = schedule_.batch_nodes.data() + ahead.nodes_begin;
      for (int32_t j = 0; j < ahead.num_nodes; ++j) {
        const int64_t row = 3 * static_cast<int64_t>(ahead_nodes[j]);
        __builtin_prefetch(d.data() + row, 0, 2);
        __builtin_prefetch(delta_.data() + row, 0, 2);
        __builtin_prefetch(w.g.data() + row, 1, 2);
      }
    }
    const ElementBatch* next =
        bi + 1 < schedule_.part_start[part + 1] ? &schedule_.batches[bi + 1] : nullptr;
    const int32_t next_count = next != nullptr ? next->count : 0;
    for (int32_t b = 0; b < batch.count; ++b) {
      for (int32_t j = next_count * b / batch.count; j < next_count * (b + 1) / batch.count; ++j) {
        __builtin_prefetch(&frames_[next->kind][next->first + j], 1);
      }
      const uint16_t* lid = lids + static_cast<int64_t>(b) * n;
      Eigen::Quaterniond& q = frames_[batch.kind][batch.first + b];
      T* cx = cols[0] + b * ld;
      T* cy = cols[1] + b * ld;
      T* cz = cols[2] + b * ld;
      if (pooled) {
        const int32_t e = schedule_.order[batch.kind][batch.first + b];
        grad = centre_gradient_[batch.kind][block.group[e]].data();
      }
#ifdef DYNSOLID_LF_AVX2
      if (n % 4 == 0) {
        LocalDeformationAvx2(n, local, lid, grad, q, rot[b], cx, cy, cz);
        continue;
      }
#endif
      if (n == fem::kCubicNodes) {
        LocalDeformation<fem::kCubicNodes>(n, local, lid, grad, q, rot[b], cx, cy, cz);
      } else if (n == 8) {
        LocalDeformation<8>(n, local, lid, grad, q, rot[b], cx, cy, cz);
      } else {
        LocalDeformation<-1>(n, local, lid, grad, q, rot[b], cx, cy, cz);
      }
    }
    // y = K dhat: sum-factorized where the group has the form (float
    // products only), else the shared dense matrices.
    bool factorized = false;
    if (pooled && batch.kind == 0) {
      // Per element at its quadrature points.
      const T* x[3] = {cols[0], cols[1], cols[2]};
      double* y[3] = {w.yx.data(), w.yy.data(), w.yz.data()};
      quadrature_.Apply<CubicPointLaw::kLocalFrame, T, T>(batch.first, batch.count, x, ld, 1, y);
      factorized = true;
    } else if (pooled) {
      // Per element, its group's small matrices (in T's precision).
      double* ys[3] = {w.yx.data(), w.yy.data(), w.yz.data()};
      for (int32_t b = 0; b < batch.count; ++b) {
        const int32_t g = block.group[schedule_.order[batch.kind][batch.first + b]];
        const T* k;
        if constexpr (std::is_same_v<T, float>) {
          k = small_f_[batch.kind][g].data();
        } else {
          k = small_[batch.kind][g].data();
        }
        for (int a = 0; a < 3; ++a) {
          SmallProduct(k + a * n * n, n, cols[a] + b * ld, ys[a] + b * ld);
        }
      }
      factorized = true;
    }
    if constexpr (std::is_same_v<T, float>) {
      if (!pooled && batch.kind == 0 && kron_[batch.group]) {
        const KroneckerStiffness& kron = *kron_[batch.group];
        kron.Apply(0, cols[0], ld, batch.count, w.yx.data());
        kron.Apply(1, cols[1], ld, batch.count, w.yy.data());
        kron.Apply(2, cols[2], ld, batch.count, w.yz.data());
        factorized = true;
      }
    }
    if (!factorized) {
      const auto& k = packed[batch.kind][batch.group];
      ApplyK(k[0], cols[0], ld, batch.count, w.yx.data());
      ApplyK(k[1], cols[1], ld, batch.count, w.yy.data());
      ApplyK(k[2], cols[2], ld, batch.count, w.yz.data());
    }
    std::fill(sums, sums + kSumStride * static_cast<int64_t>(batch.num_nodes), 0.0);
    for (int32_t b = 0; b < batch.count; ++b) {
      const uint16_t* lid = lids + static_cast<int64_t>(b) * n;
      const double* ax = w.yx.data() + b * ld;
      const double* ay = w.yy.data() + b * ld;
      const double* az = w.yz.data() + b * ld;
#ifdef DYNSOLID_LF_AVX2
      if (n % 4 == 0) {
        w.energy += RotateBackAndAddAvx2(n, rot[b], cols[0] + b * ld, cols[1] + b * ld,
                                         cols[2] + b * ld, ax, ay, az, lid, sums);
        continue;
      }
#endif
      // The element's energy 1/2 dhat . y, then its rotated sums.
      using Dhat = Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, 1>>;
      using Y = Eigen::Map<const Eigen::VectorXd>;
      const Dhat hx(cols[0] + b * ld, n), hy(cols[1] + b * ld, n), hz(cols[2] + b * ld, n);
      w.energy += 0.5 * (hx.template cast<double>().dot(Y(ax, n)) +
                         hy.template cast<double>().dot(Y(ay, n)) +
                         hz.template cast<double>().dot(Y(az, n)));
      if (n == fem::kCubicNodes) {
        RotateBackAndAdd<fem::kCubicNodes>(n, rot[b], ax, ay, az, lid, sums);
      } else if (n == 8) {
        RotateBackAndAdd<8>(n, rot[b], ax, ay, az, lid, sums);
      } else {
        RotateBackAndAdd<-1>(n, rot[b], ax, ay, az, lid, sums);
      }
    }
    ScatterRows(batch.num_nodes, nodes, sums, w.g.data());
  }
}

double LocalFrameModel::Forces(const Points& d, Points& g) {
  return float_products_ ? RunForces(d, g, packed_f_) : RunForces(d, g, packed_);
}

double LocalFrameModel::ExactForces(const Points& d, Points& g) {
  if (!float_products_) return RunForces(d, g, packed_);
  // The float matrices' entries, products in double.
  std::array<std::vector<std::array<PackedMatrix, 3>>, 3> exact;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    for (const auto& k : packed_f_[kind]) {
      exact[kind].push_back({PackedMatrix(k[0]), PackedMatrix(k[1]), PackedMatrix(k[2])});
    }
  }
  return RunForces(d, g, exact);
}

template <typename KSet>
double LocalFrameModel::RunForces(const Points& d, Points& g, const KSet& packed) {
  using T = std::conditional_t<std::is_same_v<KSet, decltype(packed_f_)>, float, double>;
  // Fixed parts, each taken by whichever thread is free (RunParts); every
  // sum is taken in an order fixed by the parts alone (see measure.h and
  // ElementSchedule).
  const auto t0 = std::chrono::steady_clock::now();
  const int parts = kForceParts;
  const int threads = pool_->size();
  pool_->RunParts(measure_.parts(), [&](int k) { measure_.ForwardPart(d, k, delta_); });
  const auto t1 = std::chrono::steady_clock::now();
  pool_->RunParts(parts, [&](int k) { RunBatches<T>(k, d, packed, work_[k]); });
  // y = dE/d delta = sum_e R_e K dhat, summed over the parts' buffers.
  pool_->Run([&](int t) {
    const int32_t n = num_nodes_;
    SumPartRows(schedule_, part_buffers_.data(), static_cast<int32_t>(int64_t{n} * t / threads),
                static_cast<int32_t>(int64_t{n} * (t + 1) / threads), y_);
  });
  double energy = 0;
  for (int k = 0; k < parts; ++k) energy += work_[k].energy;
  const auto t2 = std::chrono::steady_clock::now();
  // The force is y's pull-back through the measure: g = (d delta / d d)^T y
  // (the gradient of the energy).
  g.resize(num_nodes_, 3);
  pool_->RunParts(measure_.parts(), [&](int k) { measure_.TransposePart(d, y_, k, g); });
  const auto t3 = std::chrono::steady_clock::now();
  // The measure's phase holds both its passes (forward and transpose).
  timing_.measure_ms = std::chrono::duration<double, std::milli>((t1 - t0) + (t3 - t2)).count();
  timing_.elements_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  return energy;
}

int32_t LocalFrameModel::factorized_groups() const {
  int32_t n = 0;
  for (const auto& k : kron_) n += k.has_value() ? 1 : 0;
  return n;
}

int64_t LocalFrameModel::factorized_elements() const {
  int64_t n = 0;
  const ElementBlock& block = layout_.blocks[0];
  for (size_t g = 0; g < kron_.size(); ++g) {
    if (kron_[g]) n += block.group_start[g + 1] - block.group_start[g];
  }
  return n;
}

int64_t LocalFrameModel::shared_matrix_bytes() const {
  int64_t bytes = 0;
  for (const auto& kind : packed_)
    for (const auto& grp : kind)
      for (const auto& m : grp) bytes += m.bytes();
  for (const auto& kind : packed_f_)
    for (const auto& grp : kind)
      for (const auto& m : grp) bytes += m.bytes();
  return bytes;
}

int64_t LocalFrameModel::per_element_bytes() const {
  int64_t elements = 0;
  for (const ElementBlock& b : layout_.blocks) elements += b.size();
  const int64_t factor_bytes = quadrature_.bytes();
  return PerElementBytes(layout_) + BatchTableBytes(layout_, schedule_) +
         (elements > 0 ? (measure_.bytes() + factor_bytes) / elements : 0);
}

}  // namespace dynsolid::models
