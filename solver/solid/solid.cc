#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <numeric>
#include <optional>
#include <span>
#include <type_traits>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include "absl/strings/str_cat.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"
#include "solver/common/worker_pool.h"
#include "solver/fem/node_rows.h"
#include "solver/integrators/backward_euler.h"
#include "solver/integrators/central_difference.h"
#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/models/local_frame.h"
#include "solver/mesh/boundary.h"
#include "solver/models/measure.h"
#include "solver/scene/scene_loader.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {
namespace {

// An element's rows of the node matrix restricted to its control support:
// B (n x s) with support[a] the control point of column a, and a 128-bit
// hash of (kind, group, B) under which B^T X B products are cached
// (regular grids repeat them).
struct ElementSupport {
  std::vector<int32_t> support;
  Eigen::MatrixXd b;
  std::pair<uint64_t, uint64_t> key;
};

void GatherSupport(const subdivision::SparseMatrix& nm, const int32_t* ids, int n, int kind,
                   int32_t group, ElementSupport& out) {
  out.support.clear();
  for (int i = 0; i < n; ++i) {
    for (subdivision::SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
      out.support.push_back(static_cast<int32_t>(it.col()));
    }
  }
  std::sort(out.support.begin(), out.support.end());
  out.support.erase(std::unique(out.support.begin(), out.support.end()), out.support.end());
  const int s = static_cast<int>(out.support.size());
  out.b.setZero(n, s);
  for (int i = 0; i < n; ++i) {
    for (subdivision::SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
      out.b(i, std::lower_bound(out.support.begin(), out.support.end(), it.col()) -
                   out.support.begin()) = it.value();
    }
  }
  // FNV-1a and a multiplicative mix over the bits of (kind, group, s, B).
  uint64_t h1 = 1469598103934665603ull, h2 = 0x9e3779b97f4a7c15ull;
  auto mix = [&](uint64_t x) {
    h1 = (h1 ^ x) * 1099511628211ull;
    h2 = (h2 ^ (x + 0x632be59bd9b4e019ull + (h2 << 6) + (h2 >> 2))) * 0xff51afd7ed558ccdull;
  };
  mix(static_cast<uint64_t>(kind));
  mix(static_cast<uint64_t>(group));
  mix(static_cast<uint64_t>(s));
  for (Eigen::Index k = 0; k < out.b.size(); ++k) {
    uint64_t bits;
    std::memcpy(&bits, out.b.data() + k, sizeof(bits));
    mix(bits);
  }
  out.key = {h1, h2};
}



// A 128-bit hash (FNV-1a and a multiplicative mix, as GatherSupport's key).
class Hash128 {
 public:
  void Mix(uint64_t x) {
    h1_ = (h1_ ^ x) * 1099511628211ull;
    h2_ = (h2_ ^ (x + 0x632be59bd9b4e019ull + (h2_ << 6) + (h2_ >> 2))) * 0xff51afd7ed558ccdull;
  }
  void Doubles(const double* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) {
      uint64_t bits;
      std::memcpy(&bits, v + i, sizeof(bits));
      Mix(bits);
    }
  }
  void Ints(const int32_t* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) Mix(static_cast<uint32_t>(v[i]));
  }
  void Bytes(std::string_view s) {
    Mix(s.size());
    for (unsigned char c : s) Mix(c);
  }
  std::pair<uint64_t, uint64_t> value() const { return {h1_, h2_}; }

 private:
  uint64_t h1_ = 1469598103934665603ull, h2_ = 0x9e3779b97f4a7c15ull;
};

// FNV-1a 64 over bytes: the state's checksum.
uint64_t Checksum(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  return h;
}

// Binary state encoding: fixed-width little-endian values (this build runs
// on little-endian machines only), length-prefixed arrays.
class StateWriter {
 public:
  template <typename T>
  void Put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void Doubles(const double* v, size_t n) {
    Put<uint64_t>(n);
    out.append(reinterpret_cast<const char*>(v), n * sizeof(double));
  }
  void Matrix(const Points& m) {
    Put<int64_t>(m.rows());
    out.append(reinterpret_cast<const char*>(m.data()), m.size() * sizeof(double));
  }
  void Bytes(std::string_view s) {
    Put<uint64_t>(s.size());
    out.append(s.data(), s.size());
  }
  void Vec(const Eigen::Vector3d& v) { Doubles(v.data(), 3); }
  std::string out;
};

// Reads what StateWriter wrote; the first failure is kept (DataLoss naming
// what was being read and where) and later reads return zeros.
class StateReader {
 public:
  explicit StateReader(std::string_view bytes) : b_(bytes) {}
  template <typename T>
  T Get(const char* what) {
    T v{};
    if (Need(sizeof(T), what)) {
      std::memcpy(&v, b_.data() + pos_, sizeof(T));
      pos_ += sizeof(T);
    }
    return v;
  }
  // A count that must be at most `max` (guards allocations).
  int64_t Count(const char* what, int64_t max) {
    const uint64_t n = Get<uint64_t>(what);
    if (ok() && n > static_cast<uint64_t>(max)) {
      Fail(absl::StrCat(what, ": count ", n, " is above the possible ", max));
      return 0;
    }
    return static_cast<int64_t>(n);
  }
  std::vector<double> Doubles(const char* what, int64_t expected = -1) {
    const int64_t n = Count(what, static_cast<int64_t>((b_.size() - pos_) / sizeof(double)));
    if (expected >= 0 && ok() && n != expected) {
      Fail(absl::StrCat(what, ": ", n, " values, expected ", expected));
    }
    std::vector<double> v(ok() ? n : 0);
    if (ok() && !v.empty() && Need(v.size() * sizeof(double), what)) {
      std::memcpy(v.data(), b_.data() + pos_, v.size() * sizeof(double));
      pos_ += v.size() * sizeof(double);
    }
    return v;
  }
  Eigen::Vector3d Vec(const char* what) {
    const std::vector<double> v = Doubles(what, 3);
    return ok() ? Eigen::Vector3d(v[0], v[1], v[2]) : Eigen::Vector3d::Zero();
  }
  Points Matrix(const char* what, int64_t rows) {
    const int64_t n = Get<int64_t>(what);
    Points m;
    if (!ok()) return m;
    if (n != rows) {
      Fail(absl::StrCat(what, ": ", n, " rows, the solid has ", rows));
      return m;
    }
    m.resize(rows, 3);
    if (Need(m.size() * sizeof(double), what)) {
      std::memcpy(m.data(), b_.data() + pos_, m.size() * sizeof(double));
      pos_ += m.size() * sizeof(double);
    }
    return m;
  }
  std::string Bytes(const char* what) {
    const int64_t n = Count(what, static_cast<int64_t>(b_.size() - pos_));
    std::string s;
    if (ok() && Need(n, what)) {
      s.assign(b_.data() + pos_, n);
      pos_ += n;
    }
    return s;
  }
  void Fail(std::string message) {
    if (error_.empty()) error_ = std::move(message);
  }
  bool ok() const { return error_.empty(); }
  bool at_end() const { return pos_ == b_.size(); }
  size_t pos() const { return pos_; }
  absl::Status status() const {
    if (ok()) return absl::OkStatus();
    return absl::DataLossError(absl::StrCat("solid state: ", error_));
  }

 private:
  bool Need(size_t n, const char* what) {
    if (!ok()) return false;
    if (b_.size() - pos_ < n) {
      Fail(absl::StrCat("truncated at byte ", pos_, " while reading ", what, " (", n,
                        " bytes needed, ", b_.size() - pos_, " left)"));
      return false;
    }
    return true;
  }
  std::string_view b_;
  size_t pos_ = 0;
  std::string error_;
};

// smoothstep(t) = t^2 (3 - 2 t) on [0, 1].
double Smoothstep(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// The paint weight of a sample at rest position x in control cell `cell`
// (scene.proto MaterialPaint).
double PaintWeight(const MaterialPaint& paint, const Eigen::Vector3d& x, int32_t cell) {
  const Region& r = paint.region();
  double w = 0;
  for (int32_t c : r.control_cells()) {
    if (c == cell) w = paint.strength();
  }
  double depth = -1, band = 0;
  const double falloff = paint.falloff() > 0 ? paint.falloff() : 0.25;
  if (r.shape_case() == Region::kSphere) {
    depth = r.sphere().radius() - (x - V(r.sphere().center())).norm();
    band = falloff * r.sphere().radius();
  } else if (r.shape_case() == Region::kBox) {
    const Eigen::Vector3d lo = V(r.box().min()), hi = V(r.box().max());
    depth = std::min((x - lo).minCoeff(), (hi - x).minCoeff());
    band = falloff * 0.5 * (hi - lo).minCoeff();
  }
  if (depth >= 0) {
    const double s = band > 0 ? Smoothstep(depth / band) : 1.0;
    w = std::max(w, paint.strength() * s);
  }
  return w;
}

double Blend(double value, double target, double w) {
  if (target == 0 || w <= 0) return value;  // unset fields are not painted
  if (w >= 1) return target;
  return value + w * (target - value);
}

// A MaterialSampler for BuildElementLayout that hands out samples by their
// place (kind, element, quadrature point) rather than by position:
// BuildElementLayout samples in exactly that order (kinds 0..2, elements in
// block order, points in table order). `fn(kind, e, q, x, cell)` gives the
// sample. Each call's position is checked against the expected sample's
// (the same expression as BuildElementLayout's), so a change of that order
// is caught (ok() false) instead of silently scrambling materials.
class OrderedSampler {
 public:
  using Fn = std::function<models::MaterialPoint(int kind, int32_t e, int q,
                                                 const Eigen::Vector3d& x, int32_t cell)>;
  OrderedSampler(const models::ElementLayout& layout, const Points& rest_nodes, Fn fn)
      : layout_(layout), rest_(rest_nodes), fn_(std::move(fn)) {
    Skip();
  }
  models::MaterialPoint operator()(const Eigen::Vector3d& x, int32_t cell) {
    if (kind_ >= 3) {
      ok_ = false;
      return {};
    }
    const models::ElementBlock& block = layout_.blocks[kind_];
    const fem::KindTable& table = layout_.tables[kind_];
    const int n = block.nodes;
    const int32_t* ids = block.element_nodes(e_);
    xe_.resize(n, 3);
    for (int i = 0; i < n; ++i) xe_.row(i) = rest_.row(ids[i]);
    const Eigen::Map<const Eigen::Matrix<double, 1, Eigen::Dynamic>> nq(table.N(q_), n);
    const Eigen::Vector3d expected = (nq * xe_).transpose();
    // The same point to rounding (the layout builder and this check may
    // fuse multiply-adds differently).
    if ((expected - x).norm() > 1e-12 * (1.0 + x.norm())) ok_ = false;
    const models::MaterialPoint m = fn_(kind_, e_, q_, x, cell);
    if (++q_ == table.points) {
      q_ = 0;
      ++e_;
      Skip();
    }
    return m;
  }
  // Every sample was handed out, in order.
  bool ok() const { return ok_ && kind_ == 3; }

 private:
  void Skip() {
    while (kind_ < 3 && e_ >= layout_.blocks[kind_].size()) {
      ++kind_;
      e_ = 0;
    }
  }
  const models::ElementLayout& layout_;
  const Points& rest_;
  Fn fn_;
  int kind_ = 0;
  int32_t e_ = 0;
  int q_ = 0;
  bool ok_ = true;
  fem::NodeMatrixX3 xe_;
};


}  // namespace


absl::StatusOr<MaterialLocation> Solid::Impl::Locate(const Eigen::Vector3d& x, const Points& rest,
                                                     bool snap) const {
  // The elements' rest bounding boxes, once per layout (InstallMaterial
  // clears them) and rest nodes.
  if (boxes_rest != &rest || element_boxes[0].size() != layout->blocks[0].cell.size() ||
      element_boxes[1].size() != layout->blocks[1].cell.size() ||
      element_boxes[2].size() != layout->blocks[2].cell.size()) {
    for (int kind = 0; kind < 3; ++kind) {
      const models::ElementBlock& block = layout->blocks[kind];
      std::vector<Eigen::AlignedBox3d>& boxes = element_boxes[kind];
      boxes.resize(block.size());
      for (int32_t e = 0; e < block.size(); ++e) {
        const int32_t* ids = block.element_nodes(e);
        Eigen::Vector3d lo = rest.row(ids[0]), hi = lo;
        for (int i = 1; i < block.nodes; ++i) {
          lo = lo.cwiseMin(rest.row(ids[i]).transpose());
          hi = hi.cwiseMax(rest.row(ids[i]).transpose());
        }
        boxes[e] = Eigen::AlignedBox3d(lo, hi);
      }
    }
    boxes_rest = &rest;
  }
  std::vector<double> n, dn;
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout->blocks[kind];
    const int nn = block.nodes;
    n.resize(nn);
    dn.resize(3 * nn);
    const std::vector<Eigen::AlignedBox3d>& boxes = element_boxes[kind];
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      const Eigen::Vector3d lo = boxes[e].min(), hi = boxes[e].max();
      const double tol = 1e-9 * (hi - lo).maxCoeff();
      if (((x - lo).array() < -tol).any() || ((x - hi).array() > tol).any()) continue;
      // Newton on the element map X(u) = x.
      Eigen::Vector3d u(0.5, 0.5, 0.5);
      bool converged = false;
      for (int it = 0; it < 30; ++it) {
        fem::Shape(block.kind, u[0], u[1], u[2], n.data(), dn.data());
        Eigen::Vector3d xu = Eigen::Vector3d::Zero();
        Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
        for (int i = 0; i < nn; ++i) {
          xu += n[i] * rest.row(ids[i]).transpose();
          j += rest.row(ids[i]).transpose() * Eigen::Map<const Eigen::RowVector3d>(&dn[3 * i]);
        }
        const Eigen::Vector3d r = xu - x;
        if (r.norm() <= 1e-12 * std::max(1.0, (hi - lo).maxCoeff())) {
          converged = true;
          break;
        }
        if (std::abs(j.determinant()) < 1e-300) break;
        u -= j.inverse() * r;
        if (!u.allFinite() || u.cwiseAbs().maxCoeff() > 10) break;
      }
      if (!converged || (u.array() < -1e-9).any() || (u.array() > 1 + 1e-9).any()) continue;
      MaterialLocation m{kind, e, u.cwiseMax(0.0).cwiseMin(1.0)};
      if (snap) {
        // The paper's shortcut: the nearest quadrature point.
        const fem::KindTable& t = layout->tables[kind];
        int best = 0;
        for (int q = 1; q < t.points; ++q) {
          if ((t.uvw[q] - u).squaredNorm() < (t.uvw[best] - u).squaredNorm()) best = q;
        }
        m.uvw = t.uvw[best];
      }
      return m;
    }
  }
  return absl::InvalidArgumentError(absl::StrCat("point (", x.x(), ", ", x.y(), ", ", x.z(),
                                                  ") is not inside the solid at rest"));
}

// Mt = sum_e B_e^T M_e B_e with B_e the element's rows of the node matrix
// restricted to its control support (and Dt alike). Element matrices are
// shared per group; B_e^T M_e B_e is cached by (group, B_e values), which
// regular grids repeat.
void Solid::Impl::AssembleControlMatrices(const SparseMatrix& nm, const models::ElementLayout& layout,
                                          bool has_damping, SparseMatrix& mt, SparseMatrix& dt) {
  const int32_t nc = static_cast<int32_t>(nm.cols());
  // Small control meshes accumulate densely; large ones through triplets.
  const bool dense = nc <= 6000;
  Eigen::MatrixXd mt_dense, dt_dense;
  std::vector<Eigen::Triplet<double, int32_t>> mt_t, dt_t;
  if (dense) {
    mt_dense = Eigen::MatrixXd::Zero(nc, nc);
    if (has_damping) dt_dense = Eigen::MatrixXd::Zero(nc, nc);
  }
  ElementSupport es;
  // Cache of B^T M_e B (and B^T D_e B) by a 128-bit hash of (kind, group, B).
  std::map<std::pair<uint64_t, uint64_t>, std::pair<Eigen::MatrixXd, Eigen::MatrixXd>> cache;
  fem::NodeMatrixX3 g;
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    const fem::KindTable& table = layout.tables[kind];
    const int n = block.nodes;
    // Per group: consistent mass and damping matrices (n x n).
    std::vector<Eigen::MatrixXd> me(block.groups.size()), de(block.groups.size());
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      const models::ElementGroup& grp = block.groups[gi];
      const auto& material = layout.materials[grp.material];
      me[gi] = Eigen::MatrixXd::Zero(n, n);
      if (has_damping) de[gi] = Eigen::MatrixXd::Zero(n, n);
      for (int q = 0; q < table.points; ++q) {
        const double det = fem::PhysicalGradients(table.dN(q), grp.rest, n, g);
        const double dv = std::max(det, 0.0) * table.weight[q];
        const Eigen::Map<const Eigen::VectorXd> nq(table.N(q), n);
        me[gi].noalias() += (material[q].density * dv) * nq * nq.transpose();
        if (has_damping) de[gi].noalias() += (material[q].damping * dv) * nq * nq.transpose();
      }
    }
    for (int32_t e = 0; e < block.size(); ++e) {
      GatherSupport(nm, block.element_nodes(e), n, kind, block.group[e], es);
      const std::vector<int32_t>& support = es.support;
      const Eigen::MatrixXd& b = es.b;
      const int s = static_cast<int>(support.size());
      auto it = cache.find(es.key);
      if (it == cache.end()) {
        Eigen::MatrixXd tm = b.transpose() * me[block.group[e]] * b;
        Eigen::MatrixXd td;
        if (has_damping) td = b.transpose() * de[block.group[e]] * b;
        it = cache.emplace(es.key, std::make_pair(std::move(tm), std::move(td))).first;
      }
      const Eigen::MatrixXd& tm = it->second.first;
      const Eigen::MatrixXd& td = it->second.second;
      for (int j = 0; j < s; ++j) {
        for (int i = 0; i < s; ++i) {
          if (dense) {
            mt_dense(support[i], support[j]) += tm(i, j);
            if (has_damping) dt_dense(support[i], support[j]) += td(i, j);
          } else {
            mt_t.emplace_back(support[i], support[j], tm(i, j));
            if (has_damping) dt_t.emplace_back(support[i], support[j], td(i, j));
          }
        }
      }
    }
  }
  if (dense) {
    mt = mt_dense.sparseView(0.0, 0.0);
    if (has_damping) dt = dt_dense.sparseView(0.0, 0.0);
  } else {
    mt.resize(nc, nc);
    mt.setFromTriplets(mt_t.begin(), mt_t.end());
    if (has_damping) {
      dt.resize(nc, nc);
      dt.setFromTriplets(dt_t.begin(), dt_t.end());
    }
  }
  mt.makeCompressed();
  if (has_damping) dt.makeCompressed();
}

// omega_max^2 = largest eigenvalue of Mt^-1 Kt on the free control points,
// by power iteration with Kt v = A^T (g(d0 + eps A v) / eps) (g(d0) = 0) plus
// the penalty springs.
double Solid::Impl::EstimateOmegaMax(models::InternalForceModel& m, const SparseMatrix& mass,
                                     const std::vector<uint8_t>& fixed_set) const {
  const Points& rest = rest_nodes;
  const SparseMatrix& nm = d->node_matrix;
  const int32_t nc = static_cast<int32_t>(nm.cols());
  Points v(nc, 3), kv(nc, 3), y(nc, 3), dn(nm.rows(), 3), gn(nm.rows(), 3);
  // Deterministic start vector.
  for (int32_t i = 0; i < nc; ++i) {
    for (int c = 0; c < 3; ++c) v(i, c) = std::sin(1.0 + 7.0 * i + 3.0 * c);
  }
  integrators::ConjugateGradient cg;
  cg.Setup(&mass, fixed_set);
  double scale = 0;
  for (int32_t i = 0; i < rest.rows(); ++i) scale = std::max(scale, rest.row(i).cwiseAbs().maxCoeff());
  double lambda = 0;
  for (int it = 0; it < 40; ++it) {
    for (int32_t i = 0; i < nc; ++i) {
      if (fixed_set[i]) v.row(i).setZero();
    }
    const double vn = v.norm();
    if (vn == 0) return 0;
    v /= vn;
    const double eps = 1e-7 * std::max(scale, 1e-3);
    dn = rest + eps * (nm * v);
    m.ResetFrames();
    m.ExactForces(dn, gn);
    kv.noalias() = nm.transpose() * gn;
    kv /= eps;
    for (size_t s = 0; s < spring_point.size(); ++s) kv.row(spring_point[s]) += spring_k[s] * v.row(spring_point[s]);
    for (int32_t i = 0; i < nc; ++i) {
      if (fixed_set[i]) kv.row(i).setZero();
    }
    // Rayleigh quotient and the next iterate y = Mt^-1 Kt v.
    y.noalias() = mass * v;
    const double vmv = (v.array() * y.array()).sum();
    lambda = std::max(lambda, (v.array() * kv.array()).sum() / vmv);
    y.setZero();
    cg.Solve(kv, y, 1e-8, 500);
    v = y;
  }
  m.ResetFrames();
  return std::sqrt(std::max(lambda, 0.0));
}

void Solid::Impl::ToNodes(const Points& p, Points& out) {
  const int64_t rows = node_rows.rows();
  out.resize(rows, 3);
  const int threads = pool->size();
  pool->Run([&](int t) {
    node_rows.Multiply(p, rows * t / threads, rows * (t + 1) / threads, out);
  });
}

void Solid::Impl::FromNodes(const Points& g, Points& out) {
  const int64_t rows = node_rows.rows();
  pool->RunParts(kProjectParts, [&](int k) {
    node_rows.MultiplyTransposed(g, rows * k / kProjectParts, rows * (k + 1) / kProjectParts,
                                 project_parts[k]);
  });
  out = project_parts[0];
  for (int k = 1; k < kProjectParts; ++k) out += project_parts[k];
}

void Solid::Impl::ControlForces(const Points& p, Points& out, PhaseTimes& phases,
                                Points& pressure) {
  auto t0 = Clock::now();
  ToNodes(p, nodes);
  phases.nodes = MsSince(t0);
  t0 = Clock::now();
  last_strain_energy = model->Forces(nodes, g);
  ++element_passes;
  const models::InternalForceModel::Timing timing = model->last_timing();
  phases.measure = timing.measure_ms;
  phases.stiffness = timing.elements_ms;
  t0 = Clock::now();
  FromNodes(g, out);
  out = -out;
  phases.project = MsSince(t0);
  if (has_const_force || !spring_point.empty() || has_pressure || contact.active) {
    t0 = Clock::now();
    if (has_const_force) out += f_const;
    if (contact.active) out += contact.force;
    for (size_t s = 0; s < spring_point.size(); ++s) {
      const int32_t i = spring_point[s];
      out.row(i) -= spring_k[s] * (p.row(i) - rest_control.row(i));
    }
    if (has_pressure) {
      PressureForces(p, pressure);
      out += pressure;
    }
    phases.loads = MsSince(t0);
  }
}

void Solid::Impl::ImplicitForces(const Points& p, Points& out, PhaseTimes& phases,
                                 Points& pressure, bool energy) {
  auto t0 = Clock::now();
  ToNodes(p, nodes);
  phases.nodes = MsSince(t0);
  t0 = Clock::now();
  if (energy) {
    last_strain_energy = model->Forces(nodes, g);  // frames and the exact energy
    ++element_passes;
  } else {
    corotational->UpdateFrames(nodes);
    ++frame_passes;
  }
  phases.measure = -1;
  phases.stiffness = MsSince(t0);
  phases.project = 0;
  ExternalForces(p, out, pressure, phases);
}

void Solid::Impl::ExternalForces(const Points& p, Points& out, Points& pressure,
                                 PhaseTimes& phases) {
  const auto t0 = Clock::now();
  if (has_const_force) {
    out = f_const;
  } else {
    out.setZero(p.rows(), 3);
  }
  if (has_pressure) {
    PressureForces(p, pressure);
    out += pressure;
  }
  if (contact.active) out += contact.force;
  loads_changed = false;
  if (has_const_force || !spring_point.empty() || has_pressure || contact.active) {
    phases.loads = MsSince(t0);
  }
}

absl::Status Solid::Impl::Advance(Points& p, Points& p_prev, StepStats& stats,
                                   PhaseTimes& out) {
  PhaseTimes sub, sum;
  sum.nodes = sum.stiffness = sum.project = sum.measure = sum.solve = 0;
  if (has_const_force || !spring_point.empty() || has_pressure || contact.active) sum.loads = 0;
  auto add = [&](const PhaseTimes& t) {
    sum.nodes += t.nodes;
    sum.stiffness += t.stiffness;
    sum.measure += std::max(0.0, t.measure);
    sum.project += t.project;
    if (sum.loads >= 0) sum.loads += t.loads;
  };
  // Forces at p (kept from the end of the last step unless a rollback or
  // the first step invalidated them), so that every state's strain energy
  // is checked in the step that produced it.
  if (!forces_valid) {
    if (Folded()) {
      ImplicitForces(p, f, sub, f_press, /*energy=*/true);
    } else {
      ControlForces(p, f, sub, f_press);
    }
    add(sub);
    forces_valid = true;
  } else if (Folded() && loads_changed) {
    ExternalForces(p, f, f_press, sub);
    if (sub.loads >= 0) sum.loads += sub.loads;
  }
  if (ledger_rebase) {
    RebaseLedger(p, p_prev);
    ledger_rebase = false;
  }
  for (int k = 0; k < substeps; ++k) {
    const auto t0 = Clock::now();
    integrators::CgStats cg;
    ahead_ms = 0;
    if (Folded()) {
      ahead_from = &p;
      cg = implicit.Step(p, p_prev, force_ahead, stiffness_op, p_next, settings.cg_tolerance(),
                         settings.cg_max_iterations());
      ahead_from = nullptr;
    } else if (use_implicit) {
      cg = implicit.Step(p, p_prev, f, stiffness_op, p_next, settings.cg_tolerance(),
                         settings.cg_max_iterations());
    } else {
      cg = integrator.Step(p, p_prev, f, p_next, settings.cg_tolerance(),
                           settings.cg_max_iterations());
    }
    // The folded rhs's element pass is stiffness, not solve.
    sum.solve += MsSince(t0) - ahead_ms;
    sum.stiffness += ahead_ms;
    stats.cg_iterations += cg.iterations;
    stats.cg_max_iterations = std::max(stats.cg_max_iterations, cg.max_iterations);
    stats.cg_relative_residual = std::max(stats.cg_relative_residual, cg.relative_residual);
    forces_valid = false;
    if (!p_next.allFinite()) {
      return absl::InternalError(absl::StrCat("non-finite control points at sub-step ", k));
    }
    // Forces (and strain energy) at the new state, reused by the next sub-step.
    if (Folded()) {
      // E_R is quadratic in p with gradient A^T g_R and Hessian Kt (frames of
      // p held). The folded force was evaluated at a = p + h (v + dv0) (dv0
      // the warm start); p_next = a + h c with c = dv - dv0 the CG's
      // correction:
      //   E_R(p_next) = E_R(a) + h c . A^T g_R(A a) + h^2/2 c . Kt c,
      // Kt c from the CG's own products less the penalty springs (their
      // energy is counted apart). The strain energy of the new state in the
      // frames its step was linearized in: no element pass.
      const Points& c = implicit.last_correction();
      double quad = (c.array() * implicit.last_kt_correction().array()).sum();
      for (size_t s = 0; s < spring_point.size(); ++s) {
        quad -= spring_k[s] * c.row(spring_point[s]).squaredNorm();
      }
      const double hs = implicit.h();
      const double strain = ahead_energy + hs * (c.array() * g_ahead.array()).sum() +
                            0.5 * hs * hs * quad;
      ImplicitForces(p_next, f_next, sub, f_press_next, /*energy=*/false);
      last_strain_energy = strain;
    } else {
      ControlForces(p_next, f_next, sub, f_press_next);
    }
    add(sub);
    // Energy ledger: H = kinetic + strain + springs - external work.
    velocity = (p_next - p) / h_sub;
    mass_velocity.noalias() = mt * velocity;
    const double kinetic = 0.5 * (velocity.array() * mass_velocity.array()).sum();
    double springs = 0;
    for (size_t s = 0; s < spring_point.size(); ++s) {
      springs += 0.5 * spring_k[s] *
                 (p_next.row(spring_point[s]) - rest_control.row(spring_point[s])).squaredNorm();
    }
    if (has_const_force) ledger.work += (f_const.array() * (p_next - p).array()).sum();
    if (contact.active) ledger.work += ContactWork(p, p_next);
    // Follower pressure: trapezoidal work over the sub-step.
    if (has_pressure) {
      ledger.work += 0.5 * ((f_press + f_press_next).array() * (p_next - p).array()).sum();
    }
    const double mech = kinetic + last_strain_energy + springs;
    const double hamiltonian = mech - ledger.work;
    ledger.peak = std::max(ledger.peak, mech);
    if (!std::isfinite(hamiltonian) ||
        hamiltonian - ledger.h_min > 0.5 * ledger.peak + 1e-12 * (1.0 + ledger.peak)) {
      return absl::InternalError(absl::StrCat(
          "energy grew without external work at sub-step ", k, " (H rose by ",
          hamiltonian - ledger.h_min, " J over a peak of ", ledger.peak, " J)"));
    }
    ledger.h_min = std::min(ledger.h_min, hamiltonian);
    p_prev.swap(p);
    p.swap(p_next);
    f.swap(f_next);
    if (has_pressure) f_press.swap(f_press_next);
    forces_valid = true;
    ++stats.substeps;
  }
  out = sum;
  return absl::OkStatus();
}

Solid::Solid() = default;
Solid::~Solid() = default;

bool Solid::Impl::SameMassAndDamping(const models::ElementLayout& l) const {
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& now = layout->blocks[kind];
    const models::ElementBlock& next = l.blocks[kind];
    if (now.size() != next.size()) return false;
    for (int32_t e = 0; e < next.size(); ++e) {
      const auto& a = layout->materials[now.groups[now.group[e]].material];
      const auto& b = l.materials[next.groups[next.group[e]].material];
      if (a.size() != b.size()) return false;
      for (size_t q = 0; q < a.size(); ++q) {
        if (a[q].density != b[q].density || a[q].damping != b[q].damping) return false;
      }
    }
  }
  return true;
}

absl::StatusOr<MaterialBuild> Solid::Impl::BuildMaterial(std::unique_ptr<models::ElementLayout> l,
                                                         bool reuse, WorkerPool* model_pool) const {
  reuse = reuse && paint_reuse && model != nullptr && layout != nullptr;
  WorkerPool& threads = model_pool != nullptr ? *model_pool : *pool;
  MaterialBuild b;
  for (const auto& array : l->materials) {
    for (const auto& m : array) b.has_damping |= m.damping > 0;
  }
  // The model the scene asks for, after checking what its shared element
  // matrices would take: curved meshes share few of them.
  const bool corot = settings.model() == SolverSettings::COROTATIONAL;
  double bytes = 0;
  for (const models::ElementBlock& block : l->blocks) {
    const double n = block.nodes;
    bytes += static_cast<double>(block.groups.size()) * (corot ? 9.0 : 3.0) * n * n * 8.0;
  }
  if (bytes > kMaxSharedMatrixBytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "the ", corot ? "corotational" : "local-frame", " element matrices of this scene would take ",
        static_cast<int64_t>(bytes / 1048576.0), " MiB (", l->blocks[0].groups.size(),
        " distinct cubic elements), above the limit of ",
        static_cast<int64_t>(kMaxSharedMatrixBytes / 1048576.0),
        " MiB; use fewer subdivision levels or a more regular control mesh"));
  }
  if (corot) {
    auto m = std::make_unique<models::CorotationalModel>(*l, rest_nodes, threads,
                                                         reuse ? corotational : nullptr);
    b.corotational = m.get();
    b.shared_matrix_bytes = m->shared_matrix_bytes();
    b.element_bytes = m->per_element_bytes();
    b.model = std::move(m);
  } else {
    // One measure part per thread: its sums do not depend on the split.
    const auto* previous =
        reuse ? dynamic_cast<const models::LocalFrameModel*>(model.get()) : nullptr;
    models::DeformationMeasure measure =
        previous != nullptr
            ? previous->measure()
            : models::DeformationMeasure(d->fine(), d->elements, rest_nodes, pool->size());
    auto m = std::make_unique<models::LocalFrameModel>(
        *l, std::move(measure), d->elements.num_nodes(), threads, previous,
        settings.element_products() == SolverSettings::FLOAT);
    b.shared_matrix_bytes = m->shared_matrix_bytes();
    b.element_bytes = m->per_element_bytes();
    b.model = std::move(m);
  }
  // Mass (and damping) in control-point space.
  if (reuse && SameMassAndDamping(*l)) {
    b.mt = mt;
    b.dt = dt;
  } else {
    AssembleControlMatrices(d->node_matrix, *l, b.has_damping, b.mt, b.dt);
  }
  b.layout = std::move(l);
  return b;
}

void Solid::Impl::InstallMaterial(MaterialBuild b) {
  ++material_epoch;
  gravity_mass.resize(0);  // per material
  for (auto& boxes : element_boxes) boxes.clear();  // per layout (Locate)
  // The old model references the old layout: replace the model first.
  model = std::move(b.model);
  corotational = b.corotational;
  layout = std::move(b.layout);
  mt = std::move(b.mt);
  dt = std::move(b.dt);
  has_damping = b.has_damping;
  ++contact.epoch;  // the contact stiffness depends on the material
  ConfigureLinearized();
}

std::unique_ptr<models::InternalForceModel> Solid::Impl::ModelCopy(
    const models::ElementLayout& l, const models::InternalForceModel& live,
    WorkerPool& threads) const {
  if (const auto* corot = dynamic_cast<const models::CorotationalModel*>(&live)) {
    return std::make_unique<models::CorotationalModel>(l, rest_nodes, threads, corot);
  }
  const auto& lf = static_cast<const models::LocalFrameModel&>(live);
  return std::make_unique<models::LocalFrameModel>(
      l, lf.measure(), d->elements.num_nodes(), threads, &lf,
      settings.element_products() == SolverSettings::FLOAT);
}

bool Solid::Impl::SinglePrecisionLinearized() const {
  return use_implicit && !double_cg && settings.cg_tolerance() >= kSinglePrecisionCgTolerance;
}

void Solid::Impl::ConfigureLinearized() {
  if (corotational == nullptr) return;
  corotational->SetSinglePrecisionLinearized(SinglePrecisionLinearized());
}

int Solid::Impl::SubstepsFor(double omega) const {
  const double stable = omega > 0 ? 2.0 / omega : INFINITY;
  const double limit = settings.stability_safety() * stable;
  return std::max(1, static_cast<int>(std::ceil(settings.time_step() / limit)));
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::Create(const Scene& scene,
                                                     scene::Discretization discretization) {
  return Create(scene, std::move(discretization), 0);
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::Create(const Scene& scene,
                                                     scene::Discretization discretization,
                                                     int threads) {
  return CreateWith(scene, std::move(discretization), threads, nullptr);
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::CreateWith(
    const Scene& scene, scene::Discretization discretization, int threads,
    const std::function<models::MaterialPoint(const Eigen::Vector3d&, int32_t)>* materials) {
  if (threads < 0 || threads > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("threads: ", threads, " is outside 0-8 (0: the hardware's)"));
  }
  const auto t_build = Clock::now();
  std::unique_ptr<Solid> s(new Solid());
  s->d_ = std::move(discretization);
  s->impl_ = std::make_unique<Impl>();
  Impl& im = *s->impl_;
  im.d = &s->d_;
  im.node_rows = fem::NodeRows(s->d_.node_matrix);
  im.settings = scene::ResolvedSolverSettings(scene);
  im.surface = &s->surface_;
  if (im.settings.integrator() == SolverSettings::BACKWARD_EULER &&
      im.settings.model() != SolverSettings::COROTATIONAL) {
    return absl::UnimplementedError(
        "solver.integrator: backward_euler linearizes the corotational model (MODEL.md 5); "
        "with solver.model local_frame it is not available in this build");
  }
  s->h_ = im.settings.time_step();
  const mesh::CellComplex& control = s->d_.control();
  const int32_t nc = control.num_vertices();
  for (const Region& r : scene.constraints().fixed()) {
    for (int32_t c : r.control_cells()) {
      if (c >= control.num_cells()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "constraints.fixed: control cell ", c, " is out of range [0, ", control.num_cells(), ")"));
      }
    }
  }
  for (int i = 0; i < scene.loads().pressures_size(); ++i) {
    RETURN_IF_ERROR(im.CheckControlCells(scene.loads().pressures(i).region(),
                                         absl::StrCat("loads.pressures[", i, "].region")));
  }

  // Rest configuration.
  im.rest_control = control.positions();
  im.rest_nodes = im.node_rows.Multiply(im.rest_control);
  const Points& rest = im.rest_nodes;
  im.pool = std::make_unique<WorkerPool>(threads > 0 ? threads : BuildThreads());

  // Materials: base, then painted regions in order.
  const models::MaterialPoint base = ToPoint(scene.materials().base());
  std::vector<std::pair<const Region*, models::MaterialPoint>> painted;
  for (const MaterialRegion& mr : scene.materials().regions()) {
    painted.push_back({&mr.region(), ToPoint(mr.material())});
  }
  models::MaterialSampler sampler = [&](const Eigen::Vector3d& x, int32_t cell) {
    models::MaterialPoint m = base;
    for (const auto& [region, material] : painted) {
      if (InRegion(*region, x, cell)) m = material;
    }
    return m;
  };
  auto layout = std::make_unique<models::ElementLayout>(models::BuildElementLayout(
      s->d_.elements, rest, s->d_.hierarchy.control_cell,
      materials != nullptr ? *materials : sampler));
  if (layout->inverted_elements > 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        layout->inverted_elements, " elements are inverted at rest (det J <= 0 at a quadrature "
        "point); the subdivided mesh is too distorted for finite elements"));
  }
  s->rest_volume_ = layout->rest_volume;
  ASSIGN_OR_RETURN(MaterialBuild material, im.BuildMaterial(std::move(layout)));
  im.InstallMaterial(std::move(material));
  s->total_mass_ = im.mt.sum();
  s->BuildSurface();

  // Constraints: the scene's fixed regions, held at rest.
  im.fix_count.assign(nc, 0);
  im.fixed.assign(nc, 0);
  im.hold = im.rest_control;
  BuildReport& rep = s->report_;
  for (const PenaltySpring& spring : scene.constraints().springs()) {
    for (int32_t i = 0; i < nc; ++i) {
      bool in = InShape(spring.region(), im.rest_control.row(i).transpose());
      for (int32_t c : spring.region().control_cells()) {
        const auto verts = control.cell_vertices(c);
        in |= std::binary_search(verts.begin(), verts.end(), i);
      }
      if (in && spring.stiffness() > 0) {
        im.spring_point.push_back(i);
        im.spring_k.push_back(spring.stiffness());
      }
    }
  }
  rep.penalty_springs = static_cast<int32_t>(im.spring_point.size());

  // Loads, with ids: point forces, then pressures (then fixed regions).
  const bool snap = im.settings.snap_forces_to_quadrature();
  for (int i = 0; i < scene.loads().point_forces_size(); ++i) {
    const PointForce& pf = scene.loads().point_forces(i);
    absl::StatusOr<MaterialLocation> at = im.Locate(V(pf.position()), rest, snap);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("loads.point_forces[", i, "].position: ", at.status().message()));
    }
    im.point_loads.push_back({im.next_id++, pf, *at});
  }
  for (int i = 0; i < scene.loads().pressures_size(); ++i) {
    const Pressure& pr = scene.loads().pressures(i);
    std::vector<int32_t> quads = im.SelectQuads(pr.region());
    if (quads.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "loads.pressures[", i, "].region selects no boundary face (no face has its rest "
          "centroid in the region or its cell in control_cells)"));
    }
    im.pressures.push_back({im.next_id++, pr, std::move(quads)});
  }
  for (const Region& r : scene.constraints().fixed()) {
    Impl::FixConstraint fix{im.next_id++, r, im.SelectControlPoints(r)};
    for (int32_t i : fix.points) {
      ++im.fix_count[i];
      im.fixed[i] = 1;
    }
    im.fixes.push_back(std::move(fix));
  }
  rep.fixed_control_points = static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  im.gravity = V(scene.loads().gravity());
  im.RebuildConstantLoads();
  im.RebuildPressure();
  rep.point_forces = static_cast<int32_t>(im.point_loads.size());
  rep.gravity = im.gravity.squaredNorm() > 0;

  // Traced points.
  for (int i = 0; i < static_cast<int>(scene.traced_size()); ++i) {
    absl::StatusOr<MaterialLocation> at = im.Locate(V(scene.traced(i).position()), rest, false);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("traced[", i, "] (", scene.traced(i).name(), "): ", at.status().message()));
    }
    im.traced.push_back(*at);
    s->traced_names_.push_back(scene.traced(i).name());
  }

  // Stable step and sub-steps.
  im.omega_max = im.EstimateOmegaMax(*im.model, im.mt, im.fixed);
  im.omega_fixed = im.fixed;
  im.stable_step = im.omega_max > 0 ? 2.0 / im.omega_max : INFINITY;
  rep.omega_max = im.omega_max;
  rep.stable_step = im.stable_step;
  im.substeps = im.SubstepsFor(im.omega_max);
  // Implicit steps: asked for, or chosen by `auto` when the explicit scheme
  // would need more than kAutoImplicitSubsteps sub-steps (corotational only).
  constexpr int kAutoImplicitSubsteps = 4;
  im.use_implicit =
      im.settings.integrator() == SolverSettings::BACKWARD_EULER ||
      (im.settings.integrator() == SolverSettings::AUTO && im.corotational != nullptr &&
       im.substeps > kAutoImplicitSubsteps);
  rep.implicit = im.use_implicit;
  im.ConfigureLinearized();
  s->ReportMaterial();  // after ConfigureLinearized: the float copies, when made
  if (im.use_implicit) {
    im.substeps = 1;
    im.x_nodes.setZero(rest.rows(), 3);
    im.kx_nodes.setZero(rest.rows(), 3);
    Impl* ip = &im;
    im.stiffness_op = [ip](const Points& x, Points& out) {
      ip->ToNodes(x, ip->x_nodes);
      ip->corotational->ApplyLinearized(ip->x_nodes, ip->kx_nodes);
      ++ip->element_passes;
      ip->FromNodes(ip->kx_nodes, out);
      for (size_t s = 0; s < ip->spring_point.size(); ++s) {
        out.row(ip->spring_point[s]) += ip->spring_k[s] * x.row(ip->spring_point[s]);
      }
    };
    // F - h Kt w = f_ext(p) - A^T g_R(A (p + h w)) - springs at p + h w (the
    // frames of p held: g_R and the springs are affine in the positions);
    // w = v + dv0, the velocity plus the warm start.
    im.force_ahead = [ip](const Points& v, Points& out) {
      const auto t0 = Clock::now();
      const Points& p = *ip->ahead_from;
      ip->ahead = p + ip->implicit.h() * v;
      ip->ToNodes(ip->ahead, ip->x_nodes);
      ip->ahead_energy = ip->corotational->AffineForces(ip->x_nodes, ip->kx_nodes);
      ++ip->element_passes;
      ip->FromNodes(ip->kx_nodes, ip->g_ahead);
      out = ip->f - ip->g_ahead;
      for (size_t s = 0; s < ip->spring_point.size(); ++s) {
        const int32_t i = ip->spring_point[s];
        out.row(i) -= ip->spring_k[s] * (ip->ahead.row(i) - ip->rest_control.row(i));
      }
      ip->ahead_ms = MsSince(t0);
    };
  }
  if (im.use_implicit) {
    im.k0 = im.StiffnessMatrix(*im.layout, *im.corotational);
  }
  if (!im.use_implicit && im.substeps > im.settings.max_substeps()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.time_step: ", s->h_, " s needs ", im.substeps,
        " explicit sub-steps (stable step ", rep.stable_step, " s) but solver.max_substeps is ",
        im.settings.max_substeps(), "; lower the time step or the stiffness"));
  }
  rep.substeps = im.substeps;
  im.SetSubsteps(im.substeps, s->h_);

  // State: rest positions, initial rigid velocity.
  s->p_ = im.rest_control;
  Eigen::Vector3d centroid = im.rest_control.colwise().mean().transpose();
  const Eigen::Vector3d v0 = V(scene.initial().linear_velocity());
  const Eigen::Vector3d w0 = V(scene.initial().angular_velocity());
  s->p_prev_ = s->p_;
  for (int32_t i = 0; i < nc; ++i) {
    if (im.fixed[i]) continue;
    const Eigen::Vector3d x = im.rest_control.row(i).transpose();
    const Eigen::Vector3d v = v0 + w0.cross(x - centroid);
    s->p_prev_.row(i) = (x - im.h_sub * v).transpose();
  }
  im.nodes.setZero(rest.rows(), 3);
  im.g.setZero(rest.rows(), 3);
  im.f.setZero(nc, 3);
  im.p_next.setZero(nc, 3);
  im.backup_p.setZero(nc, 3);
  im.backup_prev.setZero(nc, 3);
  im.f_next.setZero(nc, 3);
  im.velocity = (s->p_ - s->p_prev_) / im.h_sub;
  im.mass_velocity = im.mt * im.velocity;
  // The ledger starts from the initial kinetic energy (no strain at rest).
  im.ledger.started = true;
  im.ledger.h_min = 0.5 * (im.velocity.array() * im.mass_velocity.array()).sum();
  im.ledger.peak = im.ledger.h_min;
  im.fingerprint = s->Fingerprint(scene);
  rep.build_ms = MsSince(t_build);
  return s;
}

absl::Status Solid::Step() {
  Impl& im = *impl_;
  StepStats stats;
  im.backup_p = p_;
  im.backup_prev = p_prev_;
  const Impl::Ledger ledger_at_start = im.ledger;
  const bool rebase_at_start = im.ledger_rebase;
  const int64_t passes_at_start = im.element_passes, frames_at_start = im.frame_passes;
  const int64_t rechecks_at_start = im.implicit.rechecked_starts();
  for (int attempt = 0;; ++attempt) {
    const absl::Status st = im.Advance(p_, p_prev_, stats, phases_);
    stats.element_passes = static_cast<int32_t>(im.element_passes - passes_at_start);
    stats.frame_passes = static_cast<int32_t>(im.frame_passes - frames_at_start);
    stats.warm_start_rechecks =
        static_cast<int32_t>(im.implicit.rechecked_starts() - rechecks_at_start);
    if (st.ok()) break;
    // Stability guard: back to the step's start, halve the sub-step, retry.
    p_ = im.backup_p;
    p_prev_ = im.backup_prev;
    im.ledger = ledger_at_start;
    im.ledger_rebase = rebase_at_start;
    im.model->ResetFrames();
    im.forces_valid = false;
    ++stats.rollbacks;
    ++rollbacks_;
    if (attempt >= kMaxHalvings || im.substeps * 2 > im.settings.max_substeps()) {
      last_step_ = stats;
      return absl::FailedPreconditionError(absl::StrCat(
          "step ", steps_, ": ", st.message(), "; still unstable after ", attempt + 1,
          " halvings of the sub-step (", im.substeps, " sub-steps of ", im.h_sub,
          " s); state restored to the step's start"));
    }
    const double ratio = 0.5;
    p_prev_ = p_ - ratio * (p_ - p_prev_);  // keep the velocity
    im.SetSubsteps(im.substeps * 2, h_);
    report_.substeps = im.substeps;
  }
  last_step_ = stats;
  time_ += h_;
  ++steps_;
  return absl::OkStatus();
}

void Solid::SetAtRest(const Points& p) {
  Impl& im = *impl_;
  p_ = p;
  for (int64_t i = 0; i < p_.rows(); ++i) {
    if (im.fixed[i]) p_.row(i) = im.hold.row(i);
  }
  p_prev_ = p_;
  im.model->ResetFrames();
  if (im.use_implicit) im.implicit.ResetWarmStart();
  im.forces_valid = false;
  im.ledger = Impl::Ledger();
  im.ledger.started = true;
  im.ledger.h_min = StrainEnergy(p_);
  im.ledger.peak = im.ledger.h_min;
  im.ledger_rebase = false;
}

int Solid::threads() const { return impl_->pool->size(); }

void Solid::SetPaintReuseForTesting(bool reuse) { impl_->paint_reuse = reuse; }

void Solid::SetImplicitTwoPassForTesting(bool two_pass) {
  impl_->implicit_two_pass = two_pass;
  impl_->forces_valid = false;  // `f` changes meaning
}

void Solid::SetDoublePrecisionCgForTesting() {
  impl_->double_cg = true;
  impl_->ConfigureLinearized();
  ReportMaterial();
}

void Solid::SetSubstepsForTesting(int substeps) {
  const double old_h = impl_->h_sub;
  impl_->SetSubsteps(std::max(1, substeps), h_);
  p_prev_ = p_ - (impl_->h_sub / old_h) * (p_ - p_prev_);  // keep the velocity
  report_.substeps = impl_->substeps;
}

Points Solid::InternalControlForces(const Points& p) {
  Impl& im = *impl_;
  const Points d = im.node_rows.Multiply(p);
  Points g(d.rows(), 3);
  // Frames found afresh; the solid's own (warm starts, and the frames the
  // next implicit step is linearized in) are part of its state: kept.
  const models::InternalForceModel::Frames frames = im.model->frames();
  im.model->ResetFrames();
  im.model->ExactForces(d, g);
  im.model->set_frames(frames);
  Points out;
  im.FromNodes(g, out);
  return out;
}

double Solid::StrainEnergy(const Points& p) {
  Impl& im = *impl_;
  const Points d = im.node_rows.Multiply(p);
  Points g(d.rows(), 3);
  const models::InternalForceModel::Frames frames = im.model->frames();  // as above
  im.model->ResetFrames();
  const double e = im.model->ExactForces(d, g);
  im.model->set_frames(frames);
  return e;
}

// K0 = A^T K A (3 #control square, node-major DOFs 3 i + c) of the
// corotational model at rest, plus the penalty springs, as triplets.
std::vector<Eigen::Triplet<double, int32_t>> Solid::Impl::StiffnessTriplets(
    const SparseMatrix& nm, const models::ElementLayout& layout,
    const models::CorotationalModel& corotational, const std::vector<int32_t>& spring_point,
    const std::vector<double>& spring_k) {
  std::vector<Eigen::Triplet<double, int32_t>> t;
  std::map<std::pair<uint64_t, uint64_t>, Eigen::MatrixXd> cache;
  ElementSupport es;
  // Control meshes are small: sum into a dense matrix (no triplet per
  // element entry) unless it would pass 32 MiB.
  const int64_t dofs = 3 * static_cast<int64_t>(nm.cols());
  const bool dense = dofs <= 2048;
  Eigen::MatrixXd sum;
  if (dense) sum.setZero(dofs, dofs);
  Eigen::MatrixXd kcd, tcd;
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    const int n = block.nodes;
    for (int32_t e = 0; e < block.size(); ++e) {
      GatherSupport(nm, block.element_nodes(e), n, kind, block.group[e], es);
      const std::vector<int32_t>& support = es.support;
      const Eigen::MatrixXd& b = es.b;
      const int s = static_cast<int>(support.size());
      auto it = cache.find(es.key);
      if (it == cache.end()) {
        // E^T K E with E = B (x) I3 (node-major element DOFs from control
        // DOFs), by component blocks: (E^T K E)(3a+c, 3b+d) = B^T K_cd B.
        const Eigen::MatrixXd k = corotational.K(kind, block.group[e]);
        Eigen::MatrixXd tk(3 * s, 3 * s);
        for (int c = 0; c < 3; ++c) {
          for (int d = 0; d < 3; ++d) {
            kcd.resize(n, n);
            for (int j = 0; j < n; ++j)
              for (int i = 0; i < n; ++i) kcd(i, j) = k(3 * i + c, 3 * j + d);
            tcd.noalias() = b.transpose() * (kcd * b);
            for (int bb = 0; bb < s; ++bb)
              for (int a = 0; a < s; ++a) tk(3 * a + c, 3 * bb + d) = tcd(a, bb);
          }
        }
        it = cache.emplace(es.key, std::move(tk)).first;
      }
      const Eigen::MatrixXd& tk = it->second;
      for (int c = 0; c < 3 * s; ++c) {
        const int64_t col = 3 * static_cast<int64_t>(support[c / 3]) + c % 3;
        for (int a = 0; a < 3 * s; ++a) {
          if (tk(a, c) == 0) continue;
          const int64_t row = 3 * static_cast<int64_t>(support[a / 3]) + a % 3;
          if (dense) {
            sum(row, col) += tk(a, c);
          } else {
            t.emplace_back(static_cast<int32_t>(row), static_cast<int32_t>(col), tk(a, c));
          }
        }
      }
    }
  }
  if (dense) {
    for (int64_t c = 0; c < dofs; ++c)
      for (int64_t r = 0; r < dofs; ++r) {
        if (sum(r, c) != 0) t.emplace_back(static_cast<int32_t>(r), static_cast<int32_t>(c), sum(r, c));
      }
  }
  for (size_t k = 0; k < spring_point.size(); ++k) {
    for (int c = 0; c < 3; ++c) {
      t.emplace_back(3 * spring_point[k] + c, 3 * spring_point[k] + c, spring_k[k]);
    }
  }
  return t;
}

absl::StatusOr<Points> Solid::SolveStaticLinear() {
  Impl& im = *impl_;
  if (im.corotational == nullptr) {
    return absl::FailedPreconditionError(
        "a linear static solve needs solver.model: COROTATIONAL (the local-frame model has no "
        "assembled stiffness)");
  }
  const int32_t nc = static_cast<int32_t>(d_.node_matrix.cols());
  std::vector<Eigen::Triplet<double, int32_t>> t = im.StiffnessTriplets();
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * nc);
  if (im.has_const_force) {
    for (int32_t i = 0; i < nc; ++i)
      for (int c = 0; c < 3; ++c) f[3 * i + c] = im.f_const(i, c);
  }
  // Fixed points: identity rows and columns, zero load.
  for (auto& x : t) {
    const bool fr = im.fixed[x.row() / 3] != 0, fc = im.fixed[x.col() / 3] != 0;
    if (fr || fc) x = Eigen::Triplet<double, int32_t>(x.row(), x.col(), 0.0);
  }
  for (int32_t i = 0; i < nc; ++i) {
    if (!im.fixed[i]) continue;
    for (int c = 0; c < 3; ++c) {
      t.emplace_back(3 * i + c, 3 * i + c, 1.0);
      f[3 * i + c] = 0.0;
    }
  }
  Eigen::SparseMatrix<double> k0(3 * nc, 3 * nc);
  k0.setFromTriplets(t.begin(), t.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(k0);
  if (ldlt.info() != Eigen::Success) {
    return absl::FailedPreconditionError("the static system is singular (is the solid fixed?)");
  }
  const Eigen::VectorXd u = ldlt.solve(f);
  if (ldlt.info() != Eigen::Success || !u.allFinite()) {
    return absl::FailedPreconditionError("the static system is singular (is the solid fixed?)");
  }
  Points p = im.rest_control;
  for (int32_t i = 0; i < nc; ++i)
    for (int c = 0; c < 3; ++c) p(i, c) += u[3 * i + c];
  return p;
}

std::vector<Eigen::Vector3d> Solid::TracedPositionsAt(const Points& p) const {
  const Impl& im = *impl_;
  std::vector<Eigen::Vector3d> out;
  std::vector<double> shape;
  for (const MaterialLocation& m : im.traced) out.push_back(im.PositionAt(m, p, shape));
  return out;
}

Points Solid::ApplyMass(const Points& x) const { return impl_->mt * x; }

Points Solid::NodePositions() const { return impl_->node_rows.Multiply(p_); }

Energies Solid::ComputeEnergies() const {
  const Impl& im = *impl_;
  Energies e;
  const Points v = (p_ - p_prev_) / im.h_sub;
  const Points mv = im.mt * v;
  e.kinetic = 0.5 * (v.array() * mv.array()).sum();
  e.strain = im.last_strain_energy;
  e.springs = im.SpringEnergy(p_);
  return e;
}

std::vector<Eigen::Vector3d> Solid::TracedPositions() const { return TracedPositionsAt(p_); }


// ---- Build helpers.

void Solid::ReportMaterial() {
  const Impl& im = *impl_;
  report_.cubic_groups = static_cast<int32_t>(im.layout->blocks[0].groups.size());
  report_.linear_groups = static_cast<int32_t>(im.layout->blocks[1].groups.size());
  report_.pyramid_groups = static_cast<int32_t>(im.layout->blocks[2].groups.size());
  report_.material_arrays = static_cast<int32_t>(im.layout->materials.size());
  report_.damping_matrix = im.has_damping;
  report_.node_matrix_bytes = im.node_rows.bytes();
  report_.node_matrix_float_values = im.node_rows.float_values();
  // Filled by the model; BuildMaterial read them.
  if (im.corotational != nullptr) {
    report_.single_precision_cg = im.corotational->single_precision_linearized();
    report_.shared_matrix_bytes = im.corotational->shared_matrix_bytes();
    report_.element_bytes = im.corotational->per_element_bytes();
    report_.measure_quad_path.clear();
  } else {
    const auto* lf = static_cast<const models::LocalFrameModel*>(im.model.get());
    report_.shared_matrix_bytes = lf->shared_matrix_bytes();
    report_.element_bytes = lf->per_element_bytes();
    report_.factorized_elements = lf->factorized_elements();
    report_.measure_quad_path = models::QuadPathName(lf->measure().quad_path());
  }
}

void Solid::BuildSurface() {
  Impl& im = *impl_;
  const mesh::CellComplex& fine = d_.fine();
  const mesh::BoundarySurface b = mesh::ExtractBoundary(fine);
  surface_ = Surface();
  surface_.nodes = b.mesh_vertex;
  for (int32_t f = 0; f < b.faces.rows(); ++f) {
    const std::span<const int32_t> loop = b.faces.row(f);
    const int32_t cell = fine.face_cells(b.mesh_face[f])[0];
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int32_t v : loop) centroid += im.rest_nodes.row(surface_.nodes[v]).transpose();
    centroid /= static_cast<double>(loop.size());
    auto emit = [&](int32_t a, int32_t b1, int32_t c, int32_t e) {
      surface_.quads.push_back({a, b1, c, e});
      im.quad_cell.push_back(cell);
      im.quad_centroid.push_back(centroid);
    };
    const int n = static_cast<int>(loop.size());
    if (n == 4) {
      emit(loop[0], loop[1], loop[2], loop[3]);
    } else {
      // A fan of quads (and a last triangle as a degenerate quad) from loop[0].
      for (int k = 1; k + 1 < n; k += 2) {
        emit(loop[0], loop[k], loop[k + 1], k + 2 < n ? loop[k + 2] : loop[k + 1]);
      }
    }
  }
  // The surface rows of A, for positions and pressure forces.
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (size_t i = 0; i < surface_.nodes.size(); ++i) {
    for (SparseMatrix::InnerIterator it(d_.node_matrix, surface_.nodes[i]); it; ++it) {
      t.emplace_back(static_cast<int32_t>(i), static_cast<int32_t>(it.col()), it.value());
    }
  }
  im.surface_rows.resize(static_cast<Eigen::Index>(surface_.nodes.size()), d_.node_matrix.cols());
  im.surface_rows.setFromTriplets(t.begin(), t.end());
  im.surface_rows.makeCompressed();
  im.surface_rest = im.surface_rows * im.rest_control;
}

std::pair<uint64_t, uint64_t> Solid::Fingerprint(const Scene& scene) const {
  Hash128 h;
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    scene.SerializeToCodedStream(&coded);
  }
  h.Bytes(bytes);
  const Impl& im = *impl_;
  h.Doubles(im.rest_control.data(), im.rest_control.size());
  const SparseMatrix& nm = d_.node_matrix;
  h.Mix(nm.rows());
  h.Mix(nm.cols());
  h.Ints(nm.outerIndexPtr(), nm.outerSize() + 1);
  h.Ints(nm.innerIndexPtr(), nm.nonZeros());
  h.Doubles(nm.valuePtr(), nm.nonZeros());
  for (const models::ElementBlock& block : im.layout->blocks) {
    h.Ints(block.node_ids.data(), block.node_ids.size());
  }
  return h.value();
}

// ---- Material painting.

absl::Status Solid::PaintMaterial(const MaterialPaint& paint) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedPaint> prepared, PreparePaint(paint));
  return ApplyPaint(*prepared);
}

absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> Solid::PreparePaint(
    const MaterialPaint& paint) const {
  const Impl& im = *impl_;
  RETURN_IF_ERROR(scene::ValidateMaterialPaint(paint, "paint"));
  RETURN_IF_ERROR(im.CheckControlCells(paint.region(), "paint.region"));
  auto out = std::make_shared<PreparedPaint>();
  out->paint = paint;
  out->made_for = im.PreparedForNow();
  const models::ElementLayout& old = *im.layout;
  const Material& target = paint.material();
  int64_t touched = 0;
  // Bounds for the new stable step: K' <= r K and M' >= m M in the PSD
  // sense, r the largest ratio of the isotropic stiffness's eigenvalues
  // (3 lambda + 2 mu, lambda + 2 mu, mu: the same eigenvectors for every
  // isotropic C, and the local-frame model's diagonal blocks use the last
  // two) and m the smallest density ratio over the samples; unpainted
  // samples have ratio 1. Then omega'^2 <= omega^2 r / m.
  double stiffness_ratio = 1, mass_ratio = 1;
  auto stiffness_ratios = [](const models::MaterialPoint& a, const models::MaterialPoint& b) {
    const double la = a.lame_lambda(), ma = a.lame_mu(), lb = b.lame_lambda(), mb = b.lame_mu();
    return std::max({(3 * lb + 2 * mb) / (3 * la + 2 * ma), (lb + 2 * mb) / (la + 2 * ma), mb / ma});
  };
  OrderedSampler sampler(
      old, im.rest_nodes,
      [&](int kind, int32_t e, int q, const Eigen::Vector3d& x, int32_t cell) {
        const models::ElementBlock& block = old.blocks[kind];
        models::MaterialPoint m = old.materials[block.groups[block.group[e]].material][q];
        const double w = PaintWeight(paint, x, cell);
        if (w > 0) {
          ++touched;
          m.young = Blend(m.young, target.young_modulus(), w);
          m.poisson = Blend(m.poisson, target.poisson_ratio(), w);
          m.density = Blend(m.density, target.density(), w);
          m.damping = Blend(m.damping, target.damping(), w);
          const models::MaterialPoint& was =
              old.materials[block.groups[block.group[e]].material][q];
          stiffness_ratio = std::max(stiffness_ratio, stiffness_ratios(was, m));
          mass_ratio = std::min(mass_ratio, m.density / was.density);
        }
        return m;
      });
  auto layout = std::make_unique<models::ElementLayout>(models::BuildElementLayout(
      d_.elements, im.rest_nodes, d_.hierarchy.control_cell,
      [&sampler](const Eigen::Vector3d& x, int32_t cell) { return sampler(x, cell); }));
  if (!sampler.ok()) {
    return absl::InternalError("paint: the element layout sampled materials out of order");
  }
  if (touched == 0) {
    return absl::InvalidArgumentError(
        "paint.region contains no material sample (quadrature point) of the solid");
  }
  // The new model's passes (the stable-step estimate below) run on a pool
  // of this thread's own: the solid's may be stepping.
  out->pool = std::make_unique<WorkerPool>(1);
  ASSIGN_OR_RETURN(out->build,
                   im.BuildMaterial(std::move(layout), /*reuse=*/true, out->pool.get()));
  // The stable step: from the bound when it keeps the sub-step count (or
  // the step is implicit), else estimated afresh (power iteration, the
  // costliest part of a paint). Sub-steps never drop on a paint.
  double omega = im.omega_max * std::sqrt(stiffness_ratio / mass_ratio);
  int substeps = im.use_implicit ? 1 : std::max(im.substeps, im.SubstepsFor(omega));
  if (!im.use_implicit && substeps > im.substeps) {
    omega = im.EstimateOmegaMax(*out->build.model, out->build.mt, im.fixed);
    out->estimated = true;
    substeps = std::max(im.substeps, im.SubstepsFor(omega));
  }
  if (substeps > im.settings.max_substeps()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "paint: the painted solid needs ", substeps, " explicit sub-steps (stable step ",
        2.0 / omega, " s) but solver.max_substeps is ", im.settings.max_substeps(),
        "; paint a softer or denser material, or lower the time step"));
  }
  out->omega = omega;
  out->substeps = substeps;
  if (im.use_implicit) {
    out->k0 = im.StiffnessMatrix(*out->build.layout, *out->build.corotational);
    // The float copies of the element matrices, here rather than when
    // installed (ConfigureLinearized then finds them made).
    out->build.corotational->SetSinglePrecisionLinearized(im.SinglePrecisionLinearized());
    // The integrator's matrices and factors (a paint keeps one sub-step).
    out->implicit_setup = integrators::BackwardEuler::Prepare(
        out->build.mt, out->build.has_damping ? &out->build.dt : nullptr, h_, im.fixed, &out->k0);
  }
  return out;
}

absl::Status Solid::ApplyPaint(PreparedPaint& prepared) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedPaint> again;
  PreparedPaint* p = &prepared;
  if (prepared.build.model == nullptr || prepared.made_for != im.PreparedForNow()) {
    // Prepared for a material, stable step or fixed set that has changed
    // since (or used up): the same paint on the current solid.
    ASSIGN_OR_RETURN(again, PreparePaint(prepared.paint));
    p = again.get();
  }
  MaterialBuild& build = p->build;
  const double omega = p->omega;
  const int substeps = p->substeps;
  const bool estimated = p->estimated;
  // Nothing can fail from here on.
  build.model->set_frames(im.model->frames());
  build.model->set_pool(*im.pool);
  im.InstallMaterial(std::move(build));
  if (im.use_implicit) im.k0 = std::move(p->k0);
  im.omega_max = omega;
  if (estimated) im.omega_fixed = im.fixed;  // a bound holds for the old estimate's set
  im.stable_step = omega > 0 ? 2.0 / omega : INFINITY;
  const double old_h = im.h_sub;
  im.SetSubsteps(substeps, h_, &p->implicit_setup);
  if (im.h_sub != old_h) p_prev_ = p_ - (im.h_sub / old_h) * (p_ - p_prev_);  // keep the velocity
  im.RebuildConstantLoads();  // gravity follows the density
  total_mass_ = im.mt.sum();
  ReportMaterial();
  report_.omega_max = im.omega_max;
  report_.stable_step = im.stable_step;
  report_.substeps = im.substeps;
  im.forces_valid = false;
  im.ledger_rebase = true;
  return absl::OkStatus();
}

// ---- Exact state.

namespace {
constexpr char kStateMagic[8] = {'D', 'S', 'O', 'L', 'I', 'D', 'S', 'T'};
constexpr size_t kHeaderBytes = 8 + 4 + 8 + 8 + 8;  // magic, version, fingerprint, payload size
}  // namespace

std::string Solid::SaveState() const {
  const Impl& im = *impl_;
  StateWriter w;
  w.Put<double>(time_);
  w.Put<int64_t>(steps_);
  w.Put<int64_t>(rollbacks_);
  w.Put<int32_t>(im.substeps);
  w.Put<double>(im.omega_max);
  w.Put<double>(im.stable_step);
  w.Put<uint8_t>(im.forces_valid);
  w.Put<double>(im.last_strain_energy);
  w.Put<uint8_t>(im.ledger_rebase);
  w.Put<double>(im.ledger.work);
  w.Put<double>(im.ledger.h_min);
  w.Put<double>(im.ledger.peak);
  w.Put<uint8_t>(im.ledger.started);
  w.Matrix(p_);
  w.Matrix(p_prev_);
  if (im.contact.active && im.f.rows() == im.contact.force.rows()) {
    w.Matrix(im.f - im.contact.force);  // contact loads are not state
  } else {
    w.Matrix(im.f);
  }
  w.Put<uint8_t>(im.has_pressure);
  if (im.has_pressure) w.Matrix(im.f_press);
  w.Matrix(im.hold);
  w.Put<uint8_t>(im.use_implicit);
  if (im.use_implicit) {
    const integrators::BackwardEuler::History& warm = im.implicit.history();
    w.Put<int32_t>(warm.steps);
    w.Matrix(warm.last);
    w.Matrix(warm.before);
  }
  w.Bytes(std::string_view(reinterpret_cast<const char*>(im.omega_fixed.data()),
                           im.omega_fixed.size()));
  w.Put<int64_t>(im.next_id);
  w.Vec(im.gravity);
  w.Put<uint64_t>(im.point_loads.size());
  for (const auto& l : im.point_loads) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.pressures.size());
  for (const auto& l : im.pressures) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.fixes.size());
  for (const auto& c : im.fixes) {
    w.Put<int64_t>(c.id);
    w.Bytes(c.region.SerializeAsString());
  }
  w.Put<uint64_t>(im.drags.size());
  for (const auto& d : im.drags) {
    w.Put<int64_t>(d.id);
    w.Put<uint8_t>(d.curve);
    w.Bytes(d.curve ? d.shape.SerializeAsString() : d.drag.SerializeAsString());
  }
  // Material samples: the distinct arrays and each element's array.
  const models::ElementLayout& l = *im.layout;
  w.Put<uint64_t>(l.materials.size());
  for (const auto& array : l.materials) {
    w.Doubles(reinterpret_cast<const double*>(array.data()), 4 * array.size());
  }
  for (const models::ElementBlock& block : l.blocks) {
    w.Put<uint64_t>(block.size());
    for (int32_t e = 0; e < block.size(); ++e) w.Put<int32_t>(block.groups[block.group[e]].material);
  }
  // Element frames (warm starts).
  const models::InternalForceModel::Frames& frames = im.model->frames();
  for (const auto& f : frames) {
    w.Doubles(reinterpret_cast<const double*>(f.data()), 4 * f.size());
  }
  std::string out(kStateMagic, 8);
  StateWriter h;
  h.Put<uint32_t>(kStateFormatVersion);
  h.Put<uint64_t>(im.fingerprint.first);
  h.Put<uint64_t>(im.fingerprint.second);
  h.Put<uint64_t>(w.out.size());
  out += h.out;
  out += w.out;
  const uint64_t sum = Checksum(out);
  out.append(reinterpret_cast<const char*>(&sum), sizeof(sum));
  return out;
}

absl::Status Solid::RestoreState(std::string_view bytes) { return Restore(bytes, nullptr); }

absl::Status Solid::RestoreStateAtClock(std::string_view bytes, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Restore(bytes, &clock);
}

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareStateView(
    std::string_view bytes) const {
  static_assert(sizeof(models::MaterialPoint) == 4 * sizeof(double));
  const Impl& im = *impl_;
  const int64_t nc = p_.rows();
  if (bytes.size() < kHeaderBytes + 8 || std::memcmp(bytes.data(), kStateMagic, 8) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solid state: not a dynsolid solid state (", bytes.size(),
        " bytes; it must start with \"DSOLIDST\")"));
  }
  StateReader header(bytes.substr(8, kHeaderBytes - 8));
  const uint32_t version = header.Get<uint32_t>("version");
  const uint64_t fp1 = header.Get<uint64_t>("fingerprint");
  const uint64_t fp2 = header.Get<uint64_t>("fingerprint");
  const uint64_t payload_size = header.Get<uint64_t>("payload size");
  if (version != kStateFormatVersion) {
    return absl::InvalidArgumentError(absl::StrCat("solid state: format version ", version,
                                                   "; this build reads version ",
                                                   kStateFormatVersion));
  }
  uint64_t stored_sum;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  if (Checksum(bytes.substr(0, bytes.size() - 8)) != stored_sum ||
      payload_size != bytes.size() - kHeaderBytes - 8) {
    return absl::DataLossError(absl::StrCat("solid state: checksum mismatch over ", bytes.size(),
                                            " bytes: the state is corrupt or truncated"));
  }
  if (fp1 != im.fingerprint.first || fp2 != im.fingerprint.second) {
    return absl::InvalidArgumentError(
        "solid state: saved from a different scene or discretization (fingerprint mismatch); "
        "restore into a solid created from the same scene and levels");
  }

  // Parse and check everything before changing anything.
  StateReader r(bytes.substr(kHeaderBytes, payload_size));
  const double time = r.Get<double>("time");
  const int64_t steps = r.Get<int64_t>("steps");
  const int64_t rollbacks = r.Get<int64_t>("rollbacks");
  const int32_t substeps = r.Get<int32_t>("substeps");
  const double omega = r.Get<double>("omega_max");
  const double stable = r.Get<double>("stable_step");
  const bool forces_valid = r.Get<uint8_t>("forces_valid") != 0;
  const double strain = r.Get<double>("strain energy");
  const bool rebase = r.Get<uint8_t>("ledger rebase") != 0;
  Impl::Ledger ledger;
  ledger.work = r.Get<double>("ledger");
  ledger.h_min = r.Get<double>("ledger");
  ledger.peak = r.Get<double>("ledger");
  ledger.started = r.Get<uint8_t>("ledger") != 0;
  Points p = r.Matrix("p", nc), p_prev = r.Matrix("p_prev", nc), f = r.Matrix("forces", nc);
  const bool saved_pressure = r.Get<uint8_t>("pressure flag") != 0;
  Points f_press;
  if (saved_pressure) f_press = r.Matrix("pressure forces", nc);
  Points hold = r.Matrix("held positions", nc);
  const bool saved_implicit = r.Get<uint8_t>("implicit flag") != 0;
  if (r.ok() && saved_implicit != im.use_implicit) {
    r.Fail(absl::StrCat("saved with ", saved_implicit ? "backward Euler" : "central difference",
                        ", this solid steps with the other integrator"));
  }
  integrators::BackwardEuler::History warm;
  if (saved_implicit) {
    warm.steps = r.Get<int32_t>("backward Euler warm start");
    warm.last = r.Matrix("backward Euler warm start", nc);
    warm.before = r.Matrix("backward Euler warm start", nc);
    if (r.ok() && (warm.steps < 0 || warm.steps > 2)) {
      r.Fail(absl::StrCat("backward Euler warm start over ", warm.steps, " steps (0 to 2)"));
    }
  }
  const std::string omega_fixed_bytes = r.Bytes("stable-step fixed set");
  if (r.ok() && static_cast<int64_t>(omega_fixed_bytes.size()) != nc) {
    r.Fail(absl::StrCat("stable-step fixed set: ", omega_fixed_bytes.size(), " entries, expected ",
                        nc));
  }
  const int64_t next_id = r.Get<int64_t>("next id");
  const Eigen::Vector3d gravity = r.Vec("gravity");
  if (r.ok() && (substeps < 1 || substeps > std::max(1, im.settings.max_substeps()))) {
    r.Fail(absl::StrCat("substeps ", substeps, " out of range"));
  }
  RETURN_IF_ERROR(r.status());

  // Loads and constraints: parsed, validated and located again.
  int64_t last_id = 0;
  auto check_id = [&](int64_t id, const char* what) {
    if (r.ok() && (id <= last_id || id >= next_id)) {
      r.Fail(absl::StrCat(what, " id ", id, " out of order or not below the next id ", next_id));
    }
    last_id = std::max(last_id, id);
  };
  std::vector<Impl::PointLoad> point_loads;
  const int64_t n_forces = r.Count("point forces", next_id);
  for (int64_t k = 0; k < n_forces && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("point force id");
    check_id(id, "point force");
    PointForce msg;
    if (!msg.ParseFromString(r.Bytes("point force")) && r.ok()) r.Fail("point force: bad message");
    if (!r.ok()) break;
    absl::StatusOr<MaterialLocation> at =
        im.Locate(V(msg.position()), im.rest_nodes, im.settings.snap_forces_to_quadrature());
    if (!scene::ValidatePointForce(msg, "point_force").ok() || !at.ok()) {
      r.Fail(absl::StrCat("point force ", id, " is invalid for this solid"));
      break;
    }
    point_loads.push_back({id, std::move(msg), *at});
  }
  last_id = 0;
  std::vector<Impl::PressureLoad> pressures;
  const int64_t n_pressures = r.Count("pressures", next_id);
  for (int64_t k = 0; k < n_pressures && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("pressure id");
    check_id(id, "pressure");
    Pressure msg;
    if (!msg.ParseFromString(r.Bytes("pressure")) && r.ok()) r.Fail("pressure: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> quads;
    if (scene::ValidatePressure(msg, "pressure").ok() &&
        im.CheckControlCells(msg.region(), "pressure.region").ok()) {
      quads = im.SelectQuads(msg.region());
    }
    if (quads.empty()) {
      r.Fail(absl::StrCat("pressure ", id, " is invalid for this solid"));
      break;
    }
    pressures.push_back({id, std::move(msg), std::move(quads)});
  }
  last_id = 0;
  std::vector<Impl::FixConstraint> fixes;
  std::vector<int32_t> fix_count(nc, 0);
  const int64_t n_fixes = r.Count("fixed regions", next_id);
  for (int64_t k = 0; k < n_fixes && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("fixed region id");
    check_id(id, "fixed region");
    Region region;
    if (!region.ParseFromString(r.Bytes("fixed region")) && r.ok()) r.Fail("fixed region: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> points;
    if (scene::ValidateValues(region, "region").ok() && scene::ValidateRegion(region, "region").ok() &&
        im.CheckControlCells(region, "region").ok()) {
      points = im.SelectControlPoints(region);
    }
    if (points.empty()) {
      r.Fail(absl::StrCat("fixed region ", id, " is invalid for this solid"));
      break;
    }
    for (int32_t i : points) ++fix_count[i];
    fixes.push_back({id, std::move(region), std::move(points)});
  }
  last_id = 0;
  std::vector<Impl::DragLoad> drags;
  const int64_t n_drags = r.Count("drags", next_id);
  for (int64_t k = 0; k < n_drags && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("drag id");
    check_id(id, "drag");
    const bool curve = r.Get<uint8_t>("drag kind") != 0;
    const std::string bytes = r.Bytes("drag");
    if (!r.ok()) break;
    absl::StatusOr<Impl::DragLoad> load = absl::InvalidArgumentError("bad message");
    if (curve) {
      CurveDrag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeCurve(msg);
    } else {
      Drag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeDrag(msg);
    }
    if (!load.ok()) {
      r.Fail(absl::StrCat("drag ", id, " is invalid for this solid: ", load.status().message()));
      break;
    }
    load->id = id;
    drags.push_back(*std::move(load));
  }
  if (r.ok() && saved_pressure != !(pressures.empty() && drags.empty())) {
    r.Fail("follower forces without pressures or drags");
  }
  RETURN_IF_ERROR(r.status());

  // Material samples.
  const models::ElementLayout& cur = *im.layout;
  int64_t max_arrays = 0;
  for (const models::ElementBlock& block : cur.blocks) max_arrays += block.size();
  const int64_t n_arrays = r.Count("material arrays", max_arrays);
  std::vector<std::vector<models::MaterialPoint>> arrays(r.ok() ? n_arrays : 0);
  for (int64_t k = 0; k < n_arrays && r.ok(); ++k) {
    const std::vector<double> v = r.Doubles("material array");
    if (!r.ok()) break;
    if (v.size() % 4 != 0) {
      r.Fail("material array: not whole samples");
      break;
    }
    arrays[k].resize(v.size() / 4);
    if (!v.empty()) {
      std::memcpy(static_cast<void*>(arrays[k].data()), v.data(), v.size() * sizeof(double));
    }
  }
  std::array<std::vector<int32_t>, 3> element_array;
  for (int kind = 0; kind < 3 && r.ok(); ++kind) {
    const models::ElementBlock& block = cur.blocks[kind];
    const int64_t count = r.Count("elements", max_arrays);
    if (r.ok() && count != block.size()) {
      r.Fail(absl::StrCat("material of kind ", kind, ": ", count, " elements, the solid has ",
                          block.size()));
    }
    element_array[kind].resize(r.ok() ? count : 0);
    for (int64_t e = 0; e < count && r.ok(); ++e) {
      const int32_t a = r.Get<int32_t>("element material");
      if (r.ok() && (a < 0 || a >= n_arrays ||
                     static_cast<int>(arrays[a].size()) != cur.tables[kind].points)) {
        r.Fail(absl::StrCat("element ", e, " of kind ", kind, ": bad material array ", a));
      }
      element_array[kind][e] = a;
    }
  }
  // Element frames.
  models::InternalForceModel::Frames frames;
  for (int kind = 0; kind < 3 && r.ok(); ++kind) {
    const std::vector<double> v = r.Doubles("frames", 4 * int64_t{cur.blocks[kind].size()});
    if (!r.ok()) break;
    frames[kind].resize(cur.blocks[kind].size());
    if (!v.empty()) {
      std::memcpy(static_cast<void*>(frames[kind].data()), v.data(), v.size() * sizeof(double));
    }
  }
  if (r.ok() && !r.at_end()) r.Fail(absl::StrCat("unexpected bytes after byte ", r.pos()));
  RETURN_IF_ERROR(r.status());

  // The material: rebuilt only when it differs from the current one.
  bool same_material = static_cast<size_t>(n_arrays) == cur.materials.size();
  for (int64_t k = 0; same_material && k < n_arrays; ++k) {
    same_material = arrays[k].size() == cur.materials[k].size() &&
                    std::memcmp(arrays[k].data(), cur.materials[k].data(),
                                arrays[k].size() * sizeof(models::MaterialPoint)) == 0;
  }
  for (int kind = 0; kind < 3 && same_material; ++kind) {
    const models::ElementBlock& block = cur.blocks[kind];
    for (int32_t e = 0; e < block.size() && same_material; ++e) {
      same_material = element_array[kind][e] == block.groups[block.group[e]].material;
    }
  }
  std::optional<MaterialBuild> build;
  Eigen::SparseMatrix<double> k0;
  if (!same_material) {
    OrderedSampler sampler(cur, im.rest_nodes,
                           [&](int kind, int32_t e, int q, const Eigen::Vector3d&, int32_t) {
                             return arrays[element_array[kind][e]][q];
                           });
    auto layout = std::make_unique<models::ElementLayout>(models::BuildElementLayout(
        d_.elements, im.rest_nodes, d_.hierarchy.control_cell,
        [&sampler](const Eigen::Vector3d& x, int32_t cell) { return sampler(x, cell); }));
    if (!sampler.ok()) {
      return absl::InternalError("solid state: the element layout sampled materials out of order");
    }
    ASSIGN_OR_RETURN(build, im.BuildMaterial(std::move(layout), /*reuse=*/true));
    if (im.use_implicit) {
      k0 = im.StiffnessMatrix(*build->layout, *build->corotational);
    }
  }

  // Backward Euler's Setup for the restored fixed set, sub-steps, mass and
  // K0 (made here, off the loop when a server prepares an undo).
  std::optional<integrators::BackwardEuler::Prepared> implicit_setup;
  if (im.use_implicit) {
    std::vector<uint8_t> fixed(fix_count.size());
    for (size_t i = 0; i < fixed.size(); ++i) fixed[i] = fix_count[i] > 0 ? 1 : 0;
    const SparseMatrix& mt = build ? build->mt : im.mt;
    const bool damped = build ? build->has_damping : im.has_damping;
    const SparseMatrix& dt = build ? build->dt : im.dt;
    if (build) build->corotational->SetSinglePrecisionLinearized(im.SinglePrecisionLinearized());
    implicit_setup = integrators::BackwardEuler::Prepare(mt, damped ? &dt : nullptr, h_ / substeps,
                                                         std::move(fixed), build ? &k0 : &im.k0);
  }

  auto out = std::make_shared<PreparedState>();
  out->material_epoch = im.material_epoch;
  out->time = time;
  out->steps = steps;
  out->rollbacks = rollbacks;
  out->substeps = substeps;
  out->omega = omega;
  out->stable = stable;
  out->forces_valid = forces_valid;
  out->strain = strain;
  out->rebase = rebase;
  out->ledger = ledger;
  out->p = std::move(p);
  out->p_prev = std::move(p_prev);
  out->f = std::move(f);
  out->f_press = std::move(f_press);
  out->hold = std::move(hold);
  out->warm = std::move(warm);
  out->omega_fixed_bytes = omega_fixed_bytes;
  out->next_id = next_id;
  out->gravity = gravity;
  out->point_loads = std::move(point_loads);
  out->pressures = std::move(pressures);
  out->fixes = std::move(fixes);
  out->fix_count = std::move(fix_count);
  out->drags = std::move(drags);
  out->frames = std::move(frames);
  out->build = std::move(build);
  out->k0 = std::move(k0);
  out->implicit_setup = std::move(implicit_setup);
  return out;
}

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareState(
    std::string bytes) const {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> out, PrepareStateView(bytes));
  out->bytes = std::move(bytes);
  return out;
}

absl::Status Solid::Restore(std::string_view bytes, const std::pair<double, int64_t>* clock) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> state, PrepareStateView(bytes));
  return Install(*state, clock);
}

absl::Status Solid::RestorePreparedAtClock(PreparedState& state, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Install(state, &clock);
}

absl::Status Solid::Install(PreparedState& prepared, const std::pair<double, int64_t>* clock) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedState> again;
  PreparedState* ps = &prepared;
  if (prepared.material_epoch != im.material_epoch || prepared.used) {
    // Prepared against a material that has changed since: again, now.
    if (prepared.bytes.empty()) {
      return absl::InternalError("solid state: prepared for another material, bytes not kept");
    }
    ASSIGN_OR_RETURN(again, PrepareStateView(prepared.bytes));
    ps = again.get();
  }
  PreparedState& s = *ps;
  s.used = true;
  // Nothing can fail from here on.
  if (s.build) {
    im.InstallMaterial(*std::move(s.build));
    if (im.use_implicit) im.k0 = std::move(s.k0);
    total_mass_ = im.mt.sum();
    ReportMaterial();
  }
  im.model->set_frames(s.frames);
  im.point_loads = std::move(s.point_loads);
  im.pressures = std::move(s.pressures);
  im.fixes = std::move(s.fixes);
  im.drags = std::move(s.drags);
  im.fix_count = std::move(s.fix_count);
  im.next_id = s.next_id;
  im.gravity = s.gravity;
  im.RebuildConstantLoads();
  im.RebuildPressure();
  if (im.has_pressure) im.f_press = std::move(s.f_press);
  im.hold = std::move(s.hold);
  im.omega_fixed.assign(s.omega_fixed_bytes.begin(), s.omega_fixed_bytes.end());
  im.omega_max = s.omega;
  im.stable_step = s.stable;
  for (size_t i = 0; i < im.fixed.size(); ++i) im.fixed[i] = im.fix_count[i] > 0 ? 1 : 0;
  im.SetSubsteps(s.substeps, h_, &s.implicit_setup);
  if (im.use_implicit) im.implicit.set_history(std::move(s.warm));  // checked above
  p_ = std::move(s.p);
  p_prev_ = std::move(s.p_prev);
  im.f = std::move(s.f);
  im.forces_valid = s.forces_valid;
  im.ClearContact();  // the restored `f` carries no contact load
  ++im.contact.epoch;      // and its fixed set or material may differ
  im.loads_changed = true;  // not saved: recomputing the loads changes no bit
  im.last_strain_energy = s.strain;
  im.ledger = s.ledger;
  im.ledger_rebase = s.rebase;
  time_ = clock != nullptr ? clock->first : s.time;
  steps_ = clock != nullptr ? clock->second : s.steps;
  rollbacks_ = s.rollbacks;
  report_.substeps = s.substeps;
  report_.omega_max = s.omega;
  report_.stable_step = s.stable;
  report_.point_forces = static_cast<int32_t>(im.point_loads.size());
  report_.gravity = im.gravity.squaredNorm() > 0;
  report_.fixed_control_points =
      static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  last_step_ = StepStats();
  return absl::OkStatus();
}

// ---- Boundary surface.

Points Solid::SurfacePositions() const { return impl_->surface_rows * p_; }

Solid::Bounds Solid::SurfaceBounds() const {
  const Points x = SurfacePositions();
  Bounds b;
  if (x.rows() == 0) return b;
  b.min = x.colwise().minCoeff().transpose();
  b.max = x.colwise().maxCoeff().transpose();
  return b;
}

Solid::SurfaceFields Solid::ComputeSurfaceFields() const {
  const Impl& im = *impl_;
  const Points x = SurfacePositions();
  const int64_t nv = x.rows();
  SurfaceFields out;
  out.displacement.resize(nv);
  for (int64_t i = 0; i < nv; ++i) {
    out.displacement[i] = static_cast<float>((x.row(i) - im.surface_rest.row(i)).norm());
  }
  // Strain: the largest |l / l0 - 1| over the edges and diagonals at a vertex.
  std::vector<double> strain(nv, 0.0);
  auto stretch = [&](int32_t a, int32_t b) {
    const double l0 = (im.surface_rest.row(a) - im.surface_rest.row(b)).norm();
    if (a == b || l0 <= 0) return;
    const double e = std::abs((x.row(a) - x.row(b)).norm() / l0 - 1.0);
    strain[a] = std::max(strain[a], e);
    strain[b] = std::max(strain[b], e);
  };
  for (const auto& q : surface_.quads) {
    for (int k = 0; k < 4; ++k) stretch(q[k], q[(k + 1) % 4]);
    stretch(q[0], q[2]);
    stretch(q[1], q[3]);
  }
  out.strain.assign(strain.begin(), strain.end());
  // Stiffness and mass: mean Young's modulus and density of the boundary
  // cells' elements' quadrature points, then the mean over the cells of the
  // quads around each vertex.
  const int32_t ncells = d_.fine().num_cells();
  std::vector<double> cell_young(ncells, 0.0), cell_density(ncells, 0.0);
  std::vector<int32_t> cell_count(ncells, 0);
  std::vector<uint8_t> boundary_cell(ncells, 0);
  for (int32_t c : im.quad_cell) boundary_cell[c] = 1;
  for (const models::ElementBlock& block : im.layout->blocks) {
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t c = block.cell[e];
      if (!boundary_cell[c]) continue;
      for (const models::MaterialPoint& m :
           im.layout->materials[block.groups[block.group[e]].material]) {
        cell_young[c] += m.young;
        cell_density[c] += m.density;
        ++cell_count[c];
      }
    }
  }
  std::vector<double> vyoung(nv, 0.0), vdensity(nv, 0.0);
  std::vector<int32_t> vcount(nv, 0);
  for (size_t q = 0; q < surface_.quads.size(); ++q) {
    const int32_t c = im.quad_cell[q];
    if (cell_count[c] == 0) continue;
    const double young = cell_young[c] / cell_count[c];
    const double density = cell_density[c] / cell_count[c];
    const auto& v = surface_.quads[q];
    for (int k = 0; k < 4; ++k) {
      if (k == 3 && v[3] == v[2]) continue;  // degenerate quad: a triangle
      vyoung[v[k]] += young;
      vdensity[v[k]] += density;
      ++vcount[v[k]];
    }
  }
  out.stiffness.resize(nv);
  out.mass.resize(nv);
  for (int64_t i = 0; i < nv; ++i) {
    out.stiffness[i] = vcount[i] > 0 ? static_cast<float>(vyoung[i] / vcount[i]) : 0.0f;
    out.mass[i] = vcount[i] > 0 ? static_cast<float>(vdensity[i] / vcount[i]) : 0.0f;
  }
  return out;
}

}  // namespace dynsolid::solid
