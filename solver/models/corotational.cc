#include "solver/models/corotational.h"

#include <algorithm>
#include <chrono>

#include "solver/models/rotation.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>

#include "solver/models/simd_rows.h"
#define DYNSOLID_COROT_AVX2 1
#endif

namespace dynsolid::models {
namespace {

#ifdef DYNSOLID_COROT_AVX2
using simd::LoadRow;
inline double Lane(__m256d v, int k) {
  alignas(32) double a[4];
  _mm256_store_pd(a, v);
  return a[k];
}

// F = sum_i x_i grad_i^T at the centre (grad: n x 3 row-major), summed over
// the nodes in order; ElementColumn and FrameBatches both use it, so their
// frames have the same bits.
Eigen::Matrix3d CentreGradientAvx2(int n, const double* x, const int32_t* ids,
                                   const double* grad) {
  __m256d f0 = _mm256_setzero_pd(), f1 = _mm256_setzero_pd(), f2 = _mm256_setzero_pd();
  for (int i = 0; i < n; ++i) {
    const __m256d p = LoadRow(x, ids[i]);
    f0 = _mm256_fmadd_pd(p, _mm256_broadcast_sd(grad + 3 * i), f0);
    f1 = _mm256_fmadd_pd(p, _mm256_broadcast_sd(grad + 3 * i + 1), f1);
    f2 = _mm256_fmadd_pd(p, _mm256_broadcast_sd(grad + 3 * i + 2), f2);
  }
  Eigen::Matrix3d f;
  for (int a = 0; a < 3; ++a) {
    f(a, 0) = Lane(f0, a);
    f(a, 1) = Lane(f1, a);
    f(a, 2) = Lane(f2, a);
  }
  return f;
}

// One element's column of u, AVX2: u_i = (x_i - xbar)^T R [- (x0_i - x0bar)^T]
// as node rows (3 doubles each, node-major). With `q`, R is extracted from
// F (CentreGradientAvx2) warm-started in *q; else R = *r_in. Sums run over the nodes
// in order: the bits depend on the element alone.
void ElementColumn(int n, const double* x, const double* rest, const int32_t* ids,
                   const double* grad, bool subtract_rest, const Eigen::Matrix3d* r_in, Eigen::Matrix3d& r, Eigen::Quaterniond* q,
                   int rotation_iterations, double* u) {
  __m256d sx = _mm256_setzero_pd(), s0 = _mm256_setzero_pd();
  for (int i = 0; i < n; ++i) {
    sx = _mm256_add_pd(sx, LoadRow(x, ids[i]));
    if (subtract_rest) s0 = _mm256_add_pd(s0, LoadRow(rest, ids[i]));
  }
  if (q != nullptr) {
    ExtractRotation(CentreGradientAvx2(n, x, ids, grad), *q, rotation_iterations, &r);
  } else {
    r = *r_in;
  }
  const __m256d inv_n = _mm256_set1_pd(1.0 / n);
  const __m256d xbar = _mm256_mul_pd(sx, inv_n), x0bar = _mm256_mul_pd(s0, inv_n);
  // Rows of R with a zero fourth lane: u_i = dx R(0,:) + dy R(1,:) + dz R(2,:).
  const __m256d r0 = _mm256_setr_pd(r(0, 0), r(0, 1), r(0, 2), 0);
  const __m256d r1 = _mm256_setr_pd(r(1, 0), r(1, 1), r(1, 2), 0);
  const __m256d r2 = _mm256_setr_pd(r(2, 0), r(2, 1), r(2, 2), 0);
  for (int i = 0; i < n; ++i) {
    const __m256d d = _mm256_sub_pd(LoadRow(x, ids[i]), xbar);
    __m256d v = _mm256_mul_pd(_mm256_permute4x64_pd(d, 0x00), r0);
    v = _mm256_fmadd_pd(_mm256_permute4x64_pd(d, 0x55), r1, v);
    v = _mm256_fmadd_pd(_mm256_permute4x64_pd(d, 0xAA), r2, v);
    if (subtract_rest) v = _mm256_sub_pd(v, _mm256_sub_pd(LoadRow(rest, ids[i]), x0bar));
    if (i + 1 < n) {
      _mm256_storeu_pd(u + 3 * i, v);  // lane 4 is node i + 1's x, written next
    } else {
      _mm256_maskstore_pd(u + 3 * i, _mm256_setr_epi64x(-1, -1, -1, 0), v);
    }
  }
}

// g_i += R y_i for the element's nodes (y node-major). g needs one row of
// slack past its last node (4-lane row updates; the fourth lane adds 0 to
// the next row's x; g is the calling part's own buffer).
void RotateBackAvx2(int n, const Eigen::Matrix3d& r, const double* y, const int32_t* ids,
                    double* g) {
  const __m256d c0 = _mm256_setr_pd(r(0, 0), r(1, 0), r(2, 0), 0);
  const __m256d c1 = _mm256_setr_pd(r(0, 1), r(1, 1), r(2, 1), 0);
  const __m256d c2 = _mm256_setr_pd(r(0, 2), r(1, 2), r(2, 2), 0);
  for (int i = 0; i < n; ++i) {
    __m256d v = _mm256_mul_pd(_mm256_broadcast_sd(y + 3 * i), c0);
    v = _mm256_fmadd_pd(_mm256_broadcast_sd(y + 3 * i + 1), c1, v);
    v = _mm256_fmadd_pd(_mm256_broadcast_sd(y + 3 * i + 2), c2, v);
    double* o = g + 3 * static_cast<int64_t>(ids[i]);
    _mm256_storeu_pd(o, _mm256_add_pd(_mm256_loadu_pd(o), v));
  }
}
#endif

// Elements per dense product (columns of the 3n x batch block).
constexpr int32_t kBatch = 64;
// Iteration cap of ExtractRotation (rotation.h: Newton steps where safe,
// 2-4 iterations per step from the warm start). u = R^T d - x0 is first
// order in a frame error, so the iteration runs to its stopping test; 32
// also covers a rotation of 1 rad in one call from rest.
constexpr int kRotationIterations = 32;

// The 6 x 3n strain-displacement matrix of gradients g (n x 3): strains
// xx, yy, zz, then engineering shears xy, yz, zx.
void StrainDisplacement(const fem::NodeMatrixX3& g, Eigen::Matrix<double, 6, Eigen::Dynamic>& b) {
  const int n = static_cast<int>(g.rows());
  b.setZero(6, 3 * n);
  for (int i = 0; i < n; ++i) {
    const double gx = g(i, 0), gy = g(i, 1), gz = g(i, 2);
    b(0, 3 * i + 0) = gx;
    b(1, 3 * i + 1) = gy;
    b(2, 3 * i + 2) = gz;
    b(3, 3 * i + 0) = gy;
    b(3, 3 * i + 1) = gx;
    b(4, 3 * i + 1) = gz;
    b(4, 3 * i + 2) = gy;
    b(5, 3 * i + 0) = gz;
    b(5, 3 * i + 2) = gx;
  }
}

// Isotropic elasticity in Voigt form with engineering shears.
Eigen::Matrix<double, 6, 6> Isotropic(double lambda, double mu) {
  Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Zero();
  c.topLeftCorner<3, 3>().setConstant(lambda);
  c.topLeftCorner<3, 3>().diagonal().array() += 2 * mu;
  c.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
  return c;
}

// A group's K = sum_q B_q^T C_q B_q dV_q (3n x 3n), exactly symmetric.
Eigen::MatrixXd IntegrateGroup(const fem::KindTable& table, const ElementGroup& grp,
                               const std::vector<MaterialPoint>& material) {
  const int n = table.nodes;
  fem::NodeMatrixX3 g;
  Eigen::Matrix<double, 6, Eigen::Dynamic> b;
  Eigen::MatrixXd k;
  k.setZero(3 * n, 3 * n);
  for (int q = 0; q < table.points; ++q) {
    const double det = fem::PhysicalGradients(table.dN(q), grp.rest, n, g);
    const double dv = std::max(det, 0.0) * table.weight[q];
    StrainDisplacement(g, b);
    const Eigen::Matrix<double, 6, 6> c =
        Isotropic(material[q].lame_lambda(), material[q].lame_mu()) * dv;
    k.noalias() += b.transpose() * (c * b);
  }
  // Exactly symmetric (a + b == b + a in floating point).
  return 0.5 * (k + k.transpose()).eval();
}

// F F_p^-1 (ElementFlow): the deformation gradient at the centre relative
// to the element's plastic rest shape, F_p = I + sum_i u_pi G_i^T for the
// offsets u_p (n x 3, node-major) and the centre gradients G (n x 3).
template <typename Gradient>
Eigen::Matrix3d ElasticGradient(const Eigen::Matrix3d& f, int n, const double* up,
                                const Gradient& g) {
  Eigen::Matrix3d fp = Eigen::Matrix3d::Identity();
  for (int i = 0; i < n; ++i) {
    fp += Eigen::Vector3d(up[3 * i], up[3 * i + 1], up[3 * i + 2]) * g.row(i);
  }
  return f * fp.inverse();
}

}  // namespace

CorotationalModel::CorotationalModel(const ElementLayout& layout, const Points& rest,
                                     WorkerPool& pool, const CorotationalModel* previous,
                                     int32_t quadrature_group_size, Products products)
    : layout_(layout), pool_(&pool), rest_(rest), num_nodes_(static_cast<int32_t>(rest.rows())) {
  pooled_[0] = quadrature_.Choose(layout, quadrature_group_size);
  for (int kind = 1; kind < fem::kElementKinds; ++kind) {
    pooled_[kind] =
        SmallGroups(layout.blocks[kind], std::min(quadrature_group_size, kQuadratureGroupSize));
  }
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    frames_[kind].assign(layout.blocks[kind].size(), Eigen::Quaterniond::Identity());
  }
  if (products == Products::kNow) {
    std::call_once(products_once_, [&] { BuildProducts(previous); });
  }
}

void CorotationalModel::EnsureProducts() const {
  // Lazy initialization of a model made with Products::kWhenUsed (the
  // object itself is not const: only the methods that call this are).
  std::call_once(products_once_,
                 [this] { const_cast<CorotationalModel*>(this)->BuildProducts(nullptr); });
}

void CorotationalModel::BuildProducts(const CorotationalModel* previous) {
  const ElementLayout& layout = layout_;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& block = layout.blocks[kind];
    // (A model made without products has no matrices to give.)
    const std::vector<int32_t> reuse = previous != nullptr && previous->has_products()
                                           ? MatchStiffnessGroups(layout, previous->layout_, kind)
                                           : std::vector<int32_t>(block.groups.size(), -1);
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      if (kind == 0 && pooled_[0][gi]) {
        packed_[kind].emplace_back();  // applied at the quadrature points
        continue;
      }
      if (reuse[gi] >= 0 && !(kind == 0 && previous->pooled_[0][reuse[gi]])) {
        packed_[kind].push_back(previous->packed_[kind][reuse[gi]]);
        continue;
      }
      ++integrated_groups_;
      const ElementGroup& grp = block.groups[gi];
      packed_[kind].emplace_back(
          IntegrateGroup(layout.tables[kind], grp, layout.materials[grp.material]));
    }
    if (kind > 0) {
      // Pooled small groups: their K for plain products.
      small_[kind].resize(block.groups.size());
      small_f_[kind].resize(block.groups.size());
      for (size_t gi = 0; gi < block.groups.size(); ++gi) {
        if (!pooled_[kind][gi]) continue;
        const Eigen::MatrixXd k = packed_[kind][gi].Unpack();
        const int m = static_cast<int>(k.rows());
        std::vector<double>& out = small_[kind][gi];
        out.resize(static_cast<size_t>(m) * m);
        for (int i = 0; i < m; ++i)
          for (int j = 0; j < m; ++j) out[static_cast<size_t>(i) * m + j] = k(i, j);
      }
    }
  }
  work_.resize(kForceParts);
  schedule_ = ScheduleElements(layout, kBatch, kForceParts, num_nodes_, &pooled_);
  quadrature_.Build(layout, schedule_, 1.0);
  int max_nodes = 0;
  for (const ElementBlock& block : layout.blocks) {
    if (block.size() > 0) max_nodes = std::max(max_nodes, block.nodes);
  }
  // Rows rounded up to the packed matrices' panel heights (8 and 16).
  static_assert(PackedMatrixF::kPanel % PackedMatrix::kPanel == 0);
  const int rows = (3 * max_nodes + PackedMatrixF::kPanel - 1) / PackedMatrixF::kPanel *
                   PackedMatrixF::kPanel;
  for (Workspace& w : work_) {
    w.g.setZero(num_nodes_ + 1, 3);  // one row of slack (RotateBackAvx2)
    w.u.setZero(rows, kBatch);
    w.y.setZero(rows, kBatch);
    part_buffers_.push_back(&w.g);
  }
  products_.store(true, std::memory_order_release);
  if (single_) {
    single_ = false;
    SetSinglePrecisionLinearized(true);
  }
}

void CorotationalModel::SetSinglePrecisionLinearized(bool on) {
  if (!has_products()) {
    single_ = on;  // made with the products
    return;
  }
  // The float copies depend only on the (fixed) double matrices: once made,
  // they stay right (a paint prepared off the loop makes them there).
  if (on == single_ && (!on || packed_f_[0].size() == packed_[0].size())) return;
  single_ = on;
  quadrature_.SetFloat(on);
  for (int kind = 1; kind < fem::kElementKinds; ++kind) {
    for (size_t gi = 0; gi < small_[kind].size(); ++gi) {
      if (on) {
        small_f_[kind][gi].assign(small_[kind][gi].begin(), small_[kind][gi].end());
      } else {
        small_f_[kind][gi].clear();
      }
    }
  }
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    packed_f_[kind].clear();
    if (on) {
      for (const PackedMatrix& k : packed_[kind]) packed_f_[kind].emplace_back(k);
    }
  }
  for (Workspace& w : work_) {
    if (on) {
      w.uf.setZero(w.u.rows(), w.u.cols());
    } else {
      w.uf.resize(0, 0);
    }
  }
}

void CorotationalModel::ResetFrames() {
  for (auto& f : frames_) std::fill(f.begin(), f.end(), Eigen::Quaterniond::Identity());
}

void CorotationalModel::RunBatches(int part, const Points& x, Frames* update, Workspace& w,
                                   bool subtract_rest) const {
  subtract_rest = subtract_rest || update != nullptr;
  using NodeBlock = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor, fem::kCubicNodes, 3>;
  using NodeMap = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>;
  using NodeMapConst = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>;
  NodeBlock pos, x0;
  std::array<Eigen::Matrix3d, kBatch> rot;
  // Per element of the batch: its plastic offsets (null: elastic).
  std::array<const double*, kBatch> plastic;
  const bool flowing = update != nullptr && flow_ != nullptr && flow_->flowing();
  ClearPartRows(schedule_, part, w.g);
  w.energy = 0;
  for (size_t bi = schedule_.part_start[part]; bi < schedule_.part_start[part + 1]; ++bi) {
    const ElementBatch& batch = schedule_.batches[bi];
    const ElementBlock& block = layout_.blocks[batch.kind];
    const bool pooled = batch.group == kPooled;
    const ElementGroup* grp = pooled ? nullptr : &block.groups[batch.group];
    const int n = block.nodes;
    const int m = 3 * n;
    pos.resize(n, 3);
    x0.resize(n, 3);
    auto u = w.u.topLeftCorner(m, batch.count);
    auto y = w.y.topLeftCorner(m, batch.count);
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t e = schedule_.order[batch.kind][batch.first + b];
      const int32_t* ids = block.element_nodes(e);
      if (pooled) grp = &block.groups[block.group[e]];
      plastic[b] = subtract_rest && flow_ != nullptr ? flow_->offsets(batch.kind, e) : nullptr;
#ifdef DYNSOLID_COROT_AVX2
      if (plastic[b] == nullptr) {
        // (Read only without `update`; set either way, which GCC can see.)
        const Eigen::Matrix3d r_in = update == nullptr
                                         ? frames_[batch.kind][e].toRotationMatrix()
                                         : Eigen::Matrix3d::Identity();
        ElementColumn(n, x.data(), rest_.data(), ids, grp->centre_gradient.data(), subtract_rest,
                      &r_in, rot[b],
                      update != nullptr ? &(*update)[batch.kind][e] : nullptr,
                      kRotationIterations, u.col(b).data());
        continue;
      }
#endif
      for (int i = 0; i < n; ++i) pos.row(i) = x.row(ids[i]);
      if (update != nullptr) {
        // Deformation gradient at the centre, then its rotation R_e.
        Eigen::Matrix3d f = pos.transpose().lazyProduct(grp->centre_gradient);
        if (plastic[b] != nullptr) f = ElasticGradient(f, n, plastic[b], grp->centre_gradient);
        Eigen::Quaterniond& q = (*update)[batch.kind][e];
        ExtractRotation(f, q, kRotationIterations, &rot[b]);
      } else {
        rot[b] = frames_[batch.kind][e].toRotationMatrix();
      }
      // Column b of u as n x 3 node rows: u_i^T = (x_i - xbar)^T R_e
      // [- (x0_i - x0bar)^T].
      NodeMap ub(u.col(b).data(), n, 3);
      const Eigen::RowVector3d xbar = pos.colwise().mean();
      pos.rowwise() -= xbar;
      ub.noalias() = pos.lazyProduct(rot[b]);
      if (subtract_rest) {
        for (int i = 0; i < n; ++i) x0.row(i) = rest_.row(ids[i]);
        const Eigen::RowVector3d x0bar = x0.colwise().mean();
        x0.rowwise() -= x0bar;
        ub -= x0;
        if (plastic[b] != nullptr) ub -= NodeMapConst(plastic[b], n, 3);
      }
    }
    // y = K u (K pre-packed; rows padded to the panel height), in float
    // for ApplyLinearized when asked.
    if (pooled && batch.kind != 0) {
      // Per element, its group's K (in float for ApplyLinearized when asked).
      const bool single = !subtract_rest && single_;
      for (int32_t b = 0; b < batch.count; ++b) {
        const int32_t g = block.group[schedule_.order[batch.kind][batch.first + b]];
        if (single) {
          SmallProduct(small_f_[batch.kind][g].data(), m, u.col(b).data(), y.col(b).data());
        } else {
          SmallProduct(small_[batch.kind][g].data(), m, u.col(b).data(), y.col(b).data());
        }
      }
    } else if (pooled) {
      // K u at the quadrature points: node-major columns (stride 3).
      const int64_t ld = w.u.rows();
      const double* xs[3] = {w.u.data(), w.u.data() + 1, w.u.data() + 2};
      double* ys[3] = {w.y.data(), w.y.data() + 1, w.y.data() + 2};
      if (!subtract_rest && single_) {
        quadrature_.Apply<CubicPointLaw::kIsotropic, float, double>(batch.first, batch.count, xs,
                                                                    ld, 3, ys);
      } else {
        quadrature_.Apply<CubicPointLaw::kIsotropic, double, double>(batch.first, batch.count, xs,
                                                                     ld, 3, ys);
      }
    } else if (!subtract_rest && single_) {
      auto uf = w.uf.topLeftCorner(m, batch.count);
      uf = u.cast<float>();
      packed_f_[batch.kind][batch.group].Apply(w.uf.data(), static_cast<int>(w.uf.rows()),
                                               batch.count, w.y.data(),
                                               static_cast<int>(w.y.rows()));
    } else {
      packed_[batch.kind][batch.group].Apply(w.u.data(), static_cast<int>(w.u.rows()),
                                             batch.count, w.y.data(),
                                             static_cast<int>(w.y.rows()));
    }
    for (int32_t b = 0; b < batch.count; ++b) {
      w.energy += 0.5 * u.col(b).dot(y.col(b));
      const int32_t e = schedule_.order[batch.kind][batch.first + b];
      const int32_t* ids = block.element_nodes(e);
      if (flowing && plastic[b] != nullptr) {
        flow_->Flow(batch.kind, e, u.col(b).data(), y.col(b).data());
      }
#ifdef DYNSOLID_COROT_AVX2
      RotateBackAvx2(n, rot[b], y.col(b).data(), ids, w.g.data());
      continue;
#endif
      // g_i += R_e y_i: rows of y times R_e^T.
      const NodeMap yb(y.col(b).data(), n, 3);
      pos.noalias() = yb.lazyProduct(rot[b].transpose());
      for (int i = 0; i < n; ++i) w.g.row(ids[i]) += pos.row(i);
    }
  }
}

double CorotationalModel::Forces(const Points& d, Points& g) {
  EnsureProducts();
  const auto t0 = std::chrono::steady_clock::now();
  const int parts = static_cast<int>(work_.size());
  // Each part into its own buffer (whichever thread takes it), summed in
  // part order: the same bits for any thread count.
  pool_->RunParts(parts, [&](int k) { RunBatches(k, d, &frames_, work_[k]); });
  SumParts(g);
  double energy = 0;
  for (int k = 0; k < parts; ++k) energy += work_[k].energy;
  const auto t1 = std::chrono::steady_clock::now();
  timing_.measure_ms = -1;
  timing_.elements_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  return energy;
}

void CorotationalModel::FrameBatches(int part, const Points& d) {
  using NodeBlock = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor, fem::kCubicNodes, 3>;
  NodeBlock pos;
  for (size_t bi = schedule_.part_start[part]; bi < schedule_.part_start[part + 1]; ++bi) {
    const ElementBatch& batch = schedule_.batches[bi];
    const ElementBlock& block = layout_.blocks[batch.kind];
    const int n = block.nodes;
    pos.resize(n, 3);
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t e = schedule_.order[batch.kind][batch.first + b];
      const int32_t* ids = block.element_nodes(e);
      const ElementGroup& grp = block.groups[block.group[e]];
      const double* up = flow_ != nullptr ? flow_->offsets(batch.kind, e) : nullptr;
      // As RunBatches with `update`: the same sums, the same bits.
      Eigen::Matrix3d f;
#ifdef DYNSOLID_COROT_AVX2
      if (up == nullptr) {
        f = CentreGradientAvx2(n, d.data(), ids, grp.centre_gradient.data());
      } else
#endif
      {
        for (int i = 0; i < n; ++i) pos.row(i) = d.row(ids[i]);
        f = pos.transpose().lazyProduct(grp.centre_gradient);
        if (up != nullptr) f = ElasticGradient(f, n, up, grp.centre_gradient);
      }
      ExtractRotation(f, frames_[batch.kind][e], kRotationIterations);
    }
  }
}

void CorotationalModel::UpdateFrames(const Points& d) {
  EnsureProducts();
  const auto t0 = std::chrono::steady_clock::now();
  const int parts = static_cast<int>(work_.size());
  pool_->RunParts(parts, [&](int k) { FrameBatches(k, d); });
  timing_.measure_ms = -1;
  timing_.elements_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

double CorotationalModel::AffineForces(const Points& x, Points& g) {
  EnsureProducts();
  const auto t0 = std::chrono::steady_clock::now();
  const int parts = static_cast<int>(work_.size());
  pool_->RunParts(parts, [&](int k) { RunBatches(k, x, nullptr, work_[k], true); });
  SumParts(g);
  double energy = 0;
  for (int k = 0; k < parts; ++k) energy += work_[k].energy;
  timing_.measure_ms = -1;
  timing_.elements_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return energy;
}

void CorotationalModel::ApplyLinearized(const Points& v, Points& out) const {
  EnsureProducts();
  const int parts = static_cast<int>(work_.size());
  pool_->RunParts(parts, [&](int k) { RunBatches(k, v, nullptr, work_[k]); });
  SumParts(out);
}

void CorotationalModel::SumParts(Points& out) const {
  out.resize(num_nodes_, 3);
  const int threads = pool_->size();
  pool_->Run([&](int t) {
    const int64_t n = num_nodes_;
    SumPartRows(schedule_, part_buffers_.data(), static_cast<int32_t>(n * t / threads),
                static_cast<int32_t>(n * (t + 1) / threads), out);
  });
}

int64_t CorotationalModel::shared_matrix_bytes() const {
  int64_t bytes = 0;
  for (const auto& kind : packed_)
    for (const auto& m : kind) bytes += m.bytes();
  for (const auto& kind : packed_f_)
    for (const auto& m : kind) bytes += m.bytes();
  return bytes;
}

int64_t CorotationalModel::per_element_bytes() const {
  int64_t elements = 0;
  for (const ElementBlock& b : layout_.blocks) elements += b.size();
  return PerElementBytes(layout_) + (elements > 0 ? quadrature_.bytes() / elements : 0);
}

Eigen::MatrixXd CorotationalModel::K(int kind, int32_t group) const {
  EnsureProducts();
  if (kind == 0 && pooled_[0][group]) {
    return quadrature_.Matrix(CubicPointLaw::kIsotropic, layout_, group, 1.0);
  }
  return packed_[kind][group].Unpack();
}

}  // namespace dynsolid::models
