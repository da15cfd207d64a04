#include "solver/solid/solid.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include "absl/strings/str_cat.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"
#include "solver/common/worker_pool.h"
#include "solver/integrators/backward_euler.h"
#include "solver/integrators/central_difference.h"
#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/models/local_frame.h"
#include "solver/models/measure.h"
#include "solver/scene/scene_loader.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {
namespace {

using SparseMatrix = subdivision::SparseMatrix;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

Eigen::Vector3d V(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

bool InShape(const Region& r, const Eigen::Vector3d& x) {
  switch (r.shape_case()) {
    case Region::kBox: {
      const Eigen::Vector3d lo = V(r.box().min()), hi = V(r.box().max());
      return (x.array() >= lo.array()).all() && (x.array() <= hi.array()).all();
    }
    case Region::kSphere:
      return (x - V(r.sphere().center())).norm() <= r.sphere().radius();
    default:
      return false;
  }
}

bool InRegion(const Region& r, const Eigen::Vector3d& x, int32_t control_cell) {
  if (InShape(r, x)) return true;
  for (int32_t c : r.control_cells()) {
    if (c == control_cell) return true;
  }
  return false;
}

models::MaterialPoint ToPoint(const Material& m) {
  const Material r = scene::ResolvedMaterial(m);
  return {r.young_modulus(), r.poisson_ratio(), r.density(), r.damping()};
}

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

// A material point: an element and its parametric coordinates.
struct MaterialLocation {
  int kind = 0;
  int32_t element = 0;
  Eigen::Vector3d uvw;
};

}  // namespace

struct Solid::Impl {
  scene::Discretization* d = nullptr;
  SolverSettings settings;
  std::unique_ptr<WorkerPool> pool;
  models::ElementLayout layout;
  std::unique_ptr<models::InternalForceModel> model;
  SparseMatrix mt, dt;
  bool has_damping = false;
  integrators::CentralDifference integrator;
  integrators::BackwardEuler implicit;
  bool use_implicit = false;
  models::CorotationalModel* corotational = nullptr;  // == model when corotational
  Points x_nodes, kx_nodes;
  integrators::BackwardEuler::StiffnessOperator stiffness_op;
  std::vector<uint8_t> fixed;
  // Constant external control forces (point forces, gravity): #control x 3.
  Points f_const;
  bool has_const_force = false;
  // Penalty springs on control points.
  std::vector<int32_t> spring_point;
  std::vector<double> spring_k;
  Points rest_control;
  // Traced material points.
  std::vector<MaterialLocation> traced;
  double h_sub = 0;
  int substeps = 1;
  // Per-step buffers.
  Points nodes, g, f, p_next, backup_p, backup_prev;
  double last_strain_energy = 0;

  // Shape values of a kind at (u, v, w).
  void ShapeAt(const MaterialLocation& m, std::vector<double>& n) const {
    const int nodes_per = layout.blocks[m.kind].nodes;
    n.resize(nodes_per);
    std::vector<double> dn(3 * nodes_per);
    fem::Shape(static_cast<fem::ElementKind>(m.kind), m.uvw[0], m.uvw[1], m.uvw[2], n.data(),
               dn.data());
  }

  // Energy bookkeeping for the stability guard: H = kinetic + strain +
  // spring energy - work of the constant external forces never grows for a
  // stable run (damping only lowers it).
  struct Ledger {
    double work = 0;       // J, cumulative external work
    double h_min = 0;      // lowest H so far
    double peak = 0;       // highest kinetic + strain + spring energy so far
    bool started = false;
  };
  Ledger ledger;
  Points velocity, mass_velocity, f_next;
  bool forces_valid = false;

  void SetSubsteps(int n, double h) {
    substeps = n;
    h_sub = h / n;
    if (use_implicit) {
      implicit.Setup(&mt, has_damping ? &dt : nullptr, h_sub, fixed);
      if (k0.rows() > 0) implicit.SetStiffnessPreconditioner(k0);
    } else {
      integrator.Setup(&mt, has_damping ? &dt : nullptr, h_sub, fixed);
    }
  }
  // Runs the sub-steps of one scene step from (p, p_prev); error when the
  // state goes non-finite or H grows (p, p_prev are then garbage).
  absl::Status Advance(Points& p, Points& p_prev, StepStats& stats, PhaseTimes& phases);

  std::vector<Eigen::Triplet<double, int32_t>> StiffnessTriplets() const;
  Eigen::SparseMatrix<double> k0;  // rest stiffness for the implicit preconditioner

  absl::StatusOr<MaterialLocation> Locate(const Eigen::Vector3d& x, const Points& rest,
                                          bool snap) const;
  void AssembleControlMatrices(const Points& rest);
  double EstimateOmegaMax(const Points& rest);
  void ControlForces(const Points& p, Points& out, PhaseTimes& phases);
};

absl::StatusOr<MaterialLocation> Solid::Impl::Locate(const Eigen::Vector3d& x, const Points& rest,
                                                     bool snap) const {
  std::vector<double> n, dn;
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    const int nn = block.nodes;
    n.resize(nn);
    dn.resize(3 * nn);
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      Eigen::Vector3d lo = rest.row(ids[0]), hi = lo;
      for (int i = 1; i < nn; ++i) {
        lo = lo.cwiseMin(rest.row(ids[i]).transpose());
        hi = hi.cwiseMax(rest.row(ids[i]).transpose());
      }
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
        const fem::KindTable& t = layout.tables[kind];
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
void Solid::Impl::AssembleControlMatrices(const Points& rest) {
  const SparseMatrix& nm = d->node_matrix;
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
double Solid::Impl::EstimateOmegaMax(const Points& rest) {
  const SparseMatrix& nm = d->node_matrix;
  const int32_t nc = static_cast<int32_t>(nm.cols());
  Points v(nc, 3), kv(nc, 3), y(nc, 3), dn(nm.rows(), 3), gn(nm.rows(), 3);
  // Deterministic start vector.
  for (int32_t i = 0; i < nc; ++i) {
    for (int c = 0; c < 3; ++c) v(i, c) = std::sin(1.0 + 7.0 * i + 3.0 * c);
  }
  integrators::ConjugateGradient cg;
  cg.Setup(&mt, fixed);
  double scale = 0;
  for (int32_t i = 0; i < rest.rows(); ++i) scale = std::max(scale, rest.row(i).cwiseAbs().maxCoeff());
  double lambda = 0;
  for (int it = 0; it < 40; ++it) {
    for (int32_t i = 0; i < nc; ++i) {
      if (fixed[i]) v.row(i).setZero();
    }
    const double vn = v.norm();
    if (vn == 0) return 0;
    v /= vn;
    const double eps = 1e-7 * std::max(scale, 1e-3);
    dn = rest + eps * (nm * v);
    model->ResetFrames();
    model->Forces(dn, gn);
    kv.noalias() = nm.transpose() * gn;
    kv /= eps;
    for (size_t s = 0; s < spring_point.size(); ++s) kv.row(spring_point[s]) += spring_k[s] * v.row(spring_point[s]);
    for (int32_t i = 0; i < nc; ++i) {
      if (fixed[i]) kv.row(i).setZero();
    }
    // Rayleigh quotient and the next iterate y = Mt^-1 Kt v.
    y.noalias() = mt * v;
    const double vmv = (v.array() * y.array()).sum();
    lambda = std::max(lambda, (v.array() * kv.array()).sum() / vmv);
    y.setZero();
    cg.Solve(kv, y, 1e-8, 500);
    v = y;
  }
  model->ResetFrames();
  return std::sqrt(std::max(lambda, 0.0));
}

void Solid::Impl::ControlForces(const Points& p, Points& out, PhaseTimes& phases) {
  auto t0 = Clock::now();
  nodes.noalias() = d->node_matrix * p;
  phases.nodes = MsSince(t0);
  t0 = Clock::now();
  last_strain_energy = model->Forces(nodes, g);
  const models::InternalForceModel::Timing timing = model->last_timing();
  phases.measure = timing.measure_ms;
  phases.stiffness = timing.elements_ms;
  t0 = Clock::now();
  out.noalias() = d->node_matrix.transpose() * g;
  out = -out;
  phases.project = MsSince(t0);
  if (has_const_force || !spring_point.empty()) {
    t0 = Clock::now();
    if (has_const_force) out += f_const;
    for (size_t s = 0; s < spring_point.size(); ++s) {
      const int32_t i = spring_point[s];
      out.row(i) -= spring_k[s] * (p.row(i) - rest_control.row(i));
    }
    phases.loads = MsSince(t0);
  }
}

absl::Status Solid::Impl::Advance(Points& p, Points& p_prev, StepStats& stats,
                                   PhaseTimes& out) {
  PhaseTimes sub, sum;
  sum.nodes = sum.stiffness = sum.project = sum.measure = sum.solve = 0;
  if (has_const_force || !spring_point.empty()) sum.loads = 0;
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
    ControlForces(p, f, sub);
    add(sub);
    forces_valid = true;
  }
  for (int k = 0; k < substeps; ++k) {
    const auto t0 = Clock::now();
    const integrators::CgStats cg =
        use_implicit ? implicit.Step(p, p_prev, f, stiffness_op, p_next, settings.cg_tolerance(),
                                     settings.cg_max_iterations())
                     : integrator.Step(p, p_prev, f, p_next, settings.cg_tolerance(),
                                       settings.cg_max_iterations());
    sum.solve += MsSince(t0);
    stats.cg_iterations += cg.iterations;
    stats.cg_max_iterations = std::max(stats.cg_max_iterations, cg.max_iterations);
    stats.cg_relative_residual = std::max(stats.cg_relative_residual, cg.relative_residual);
    forces_valid = false;
    if (!p_next.allFinite()) {
      return absl::InternalError(absl::StrCat("non-finite control points at sub-step ", k));
    }
    // Forces (and strain energy) at the new state, reused by the next sub-step.
    ControlForces(p_next, f_next, sub);
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
    forces_valid = true;
    ++stats.substeps;
  }
  out = sum;
  return absl::OkStatus();
}

Solid::Solid() = default;
Solid::~Solid() = default;

absl::StatusOr<std::unique_ptr<Solid>> Solid::Create(const Scene& scene,
                                                     scene::Discretization discretization) {
  const auto t_build = Clock::now();
  std::unique_ptr<Solid> s(new Solid());
  s->d_ = std::move(discretization);
  s->impl_ = std::make_unique<Impl>();
  Impl& im = *s->impl_;
  im.d = &s->d_;
  im.settings = scene::ResolvedSolverSettings(scene);
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

  // Rest configuration.
  im.rest_control = control.positions();
  const Points rest = s->d_.node_matrix * im.rest_control;
  im.pool = std::make_unique<WorkerPool>(BuildThreads());

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
  im.layout = models::BuildElementLayout(s->d_.elements, rest, s->d_.hierarchy.control_cell, sampler);
  if (im.layout.inverted_elements > 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        im.layout.inverted_elements, " elements are inverted at rest (det J <= 0 at a quadrature "
        "point); the subdivided mesh is too distorted for finite elements"));
  }
  s->rest_volume_ = im.layout.rest_volume;
  for (const auto& array : im.layout.materials) {
    for (const auto& m : array) im.has_damping |= m.damping > 0;
  }

  // The model the scene asks for, after checking what its shared element
  // matrices would take: curved meshes share few of them.
  BuildReport& rep = s->report_;
  {
    const bool corot = im.settings.model() == SolverSettings::COROTATIONAL;
    double bytes = 0;
    for (const models::ElementBlock& block : im.layout.blocks) {
      const double n = block.nodes;
      bytes += static_cast<double>(block.groups.size()) * (corot ? 9.0 : 3.0) * n * n * 8.0;
    }
    if (bytes > kMaxSharedMatrixBytes) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "the ", corot ? "corotational" : "local-frame", " element matrices of this scene would take ",
          static_cast<int64_t>(bytes / 1048576.0), " MiB (", im.layout.blocks[0].groups.size(),
          " distinct cubic elements), above the limit of ",
          static_cast<int64_t>(kMaxSharedMatrixBytes / 1048576.0),
          " MiB; use fewer subdivision levels or a more regular control mesh"));
    }
  }
  if (im.settings.model() == SolverSettings::COROTATIONAL) {
    auto model = std::make_unique<models::CorotationalModel>(im.layout, rest, *im.pool);
    im.corotational = model.get();
    rep.shared_matrix_bytes = model->shared_matrix_bytes();
    rep.element_bytes = model->per_element_bytes();
    im.model = std::move(model);
  } else {
    // One measure part per thread: its sums do not depend on the split.
    models::DeformationMeasure measure(s->d_.fine(), s->d_.elements, rest, im.pool->size());
    auto model = std::make_unique<models::LocalFrameModel>(im.layout, std::move(measure),
                                                            s->d_.elements.num_nodes(), *im.pool);
    rep.shared_matrix_bytes = model->shared_matrix_bytes();
    rep.element_bytes = model->per_element_bytes();
    im.model = std::move(model);
  }
  rep.cubic_groups = static_cast<int32_t>(im.layout.blocks[0].groups.size());
  rep.linear_groups = static_cast<int32_t>(im.layout.blocks[1].groups.size());
  rep.pyramid_groups = static_cast<int32_t>(im.layout.blocks[2].groups.size());
  rep.material_arrays = static_cast<int32_t>(im.layout.materials.size());
  rep.damping_matrix = im.has_damping;

  // Mass (and damping) in control-point space.
  im.AssembleControlMatrices(rest);
  s->total_mass_ = im.mt.sum();

  // Constraints.
  im.fixed.assign(nc, 0);
  for (const Region& r : scene.constraints().fixed()) {
    for (int32_t i = 0; i < nc; ++i) {
      if (InShape(r, im.rest_control.row(i).transpose())) im.fixed[i] = 1;
    }
    for (int32_t c : r.control_cells()) {
      for (int32_t v : control.cell_vertices(c)) im.fixed[v] = 1;
    }
  }
  rep.fixed_control_points = static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
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

  // Constant loads in control space.
  Points fd = Points::Zero(rest.rows(), 3);
  const bool snap = im.settings.snap_forces_to_quadrature();
  std::vector<double> shape;
  for (int i = 0; i < scene.loads().point_forces_size(); ++i) {
    const PointForce& pf = scene.loads().point_forces(i);
    absl::StatusOr<MaterialLocation> at = im.Locate(V(pf.position()), rest, snap);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("loads.point_forces[", i, "].position: ", at.status().message()));
    }
    im.ShapeAt(*at, shape);
    const int32_t* ids = im.layout.blocks[at->kind].element_nodes(at->element);
    for (size_t k = 0; k < shape.size(); ++k) fd.row(ids[k]) += shape[k] * V(pf.force()).transpose();
    ++rep.point_forces;
  }
  const Eigen::Vector3d gravity = V(scene.loads().gravity());
  if (gravity.squaredNorm() > 0) {
    // Body force mu g: f_i = g int mu N_i dV.
    rep.gravity = true;
    fem::NodeMatrixX3 gr;
    for (int kind = 0; kind < 3; ++kind) {
      const models::ElementBlock& block = im.layout.blocks[kind];
      const fem::KindTable& table = im.layout.tables[kind];
      std::vector<Eigen::VectorXd> weights(block.groups.size());
      for (size_t gi = 0; gi < block.groups.size(); ++gi) {
        const auto& grp = block.groups[gi];
        weights[gi] = Eigen::VectorXd::Zero(block.nodes);
        for (int q = 0; q < table.points; ++q) {
          const double det = fem::PhysicalGradients(table.dN(q), grp.rest, block.nodes, gr);
          weights[gi] += (im.layout.materials[grp.material][q].density * std::max(det, 0.0) *
                          table.weight[q]) *
                         Eigen::Map<const Eigen::VectorXd>(table.N(q), block.nodes);
        }
      }
      for (int32_t e = 0; e < block.size(); ++e) {
        const int32_t* ids = block.element_nodes(e);
        for (int k = 0; k < block.nodes; ++k) {
          fd.row(ids[k]) += weights[block.group[e]][k] * gravity.transpose();
        }
      }
    }
  }
  im.has_const_force = rep.point_forces > 0 || rep.gravity;
  if (im.has_const_force) im.f_const = s->d_.node_matrix.transpose() * fd;

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
  rep.omega_max = im.EstimateOmegaMax(rest);
  rep.stable_step = rep.omega_max > 0 ? 2.0 / rep.omega_max : INFINITY;
  const double limit = im.settings.stability_safety() * rep.stable_step;
  im.substeps = std::max(1, static_cast<int>(std::ceil(s->h_ / limit)));
  // Implicit steps: asked for, or chosen by `auto` when the explicit scheme
  // would need more than kAutoImplicitSubsteps sub-steps (corotational only).
  constexpr int kAutoImplicitSubsteps = 4;
  im.use_implicit =
      im.settings.integrator() == SolverSettings::BACKWARD_EULER ||
      (im.settings.integrator() == SolverSettings::AUTO && im.corotational != nullptr &&
       im.substeps > kAutoImplicitSubsteps);
  rep.implicit = im.use_implicit;
  if (im.use_implicit) {
    im.substeps = 1;
    im.x_nodes.setZero(rest.rows(), 3);
    im.kx_nodes.setZero(rest.rows(), 3);
    Impl* ip = &im;
    im.stiffness_op = [ip](const Points& x, Points& out) {
      ip->x_nodes.noalias() = ip->d->node_matrix * x;
      ip->corotational->ApplyLinearized(ip->x_nodes, ip->kx_nodes);
      out.noalias() = ip->d->node_matrix.transpose() * ip->kx_nodes;
      for (size_t s = 0; s < ip->spring_point.size(); ++s) {
        out.row(ip->spring_point[s]) += ip->spring_k[s] * x.row(ip->spring_point[s]);
      }
    };
  }
  if (im.use_implicit) {
    const std::vector<Eigen::Triplet<double, int32_t>> t = im.StiffnessTriplets();
    im.k0.resize(3 * nc, 3 * nc);
    im.k0.setFromTriplets(t.begin(), t.end());
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
  rep.build_ms = MsSince(t_build);
  return s;
}

absl::Status Solid::Step() {
  Impl& im = *impl_;
  StepStats stats;
  im.backup_p = p_;
  im.backup_prev = p_prev_;
  const Impl::Ledger ledger_at_start = im.ledger;
  for (int attempt = 0;; ++attempt) {
    const absl::Status st = im.Advance(p_, p_prev_, stats, phases_);
    if (st.ok()) break;
    // Stability guard: back to the step's start, halve the sub-step, retry.
    p_ = im.backup_p;
    p_prev_ = im.backup_prev;
    im.ledger = ledger_at_start;
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
    if (im.fixed[i]) p_.row(i) = im.rest_control.row(i);
  }
  p_prev_ = p_;
  im.model->ResetFrames();
  im.forces_valid = false;
  im.ledger = Impl::Ledger();
  im.ledger.started = true;
  im.ledger.h_min = StrainEnergy(p_);
  im.ledger.peak = im.ledger.h_min;
}

void Solid::SetSubstepsForTesting(int substeps) {
  const double old_h = impl_->h_sub;
  impl_->SetSubsteps(std::max(1, substeps), h_);
  p_prev_ = p_ - (impl_->h_sub / old_h) * (p_ - p_prev_);  // keep the velocity
  report_.substeps = impl_->substeps;
}

Points Solid::InternalControlForces(const Points& p) {
  Impl& im = *impl_;
  const Points d = d_.node_matrix * p;
  Points g(d.rows(), 3);
  im.model->ResetFrames();
  im.model->Forces(d, g);
  im.model->ResetFrames();
  return d_.node_matrix.transpose() * g;
}

double Solid::StrainEnergy(const Points& p) {
  Impl& im = *impl_;
  const Points d = d_.node_matrix * p;
  Points g(d.rows(), 3);
  im.model->ResetFrames();
  const double e = im.model->Forces(d, g);
  im.model->ResetFrames();
  return e;
}

// K0 = A^T K A (3 #control square, node-major DOFs 3 i + c) of the
// corotational model at rest, plus the penalty springs, as triplets.
std::vector<Eigen::Triplet<double, int32_t>> Solid::Impl::StiffnessTriplets() const {
  const SparseMatrix& nm = d->node_matrix;
  std::vector<Eigen::Triplet<double, int32_t>> t;
  std::map<std::pair<uint64_t, uint64_t>, Eigen::MatrixXd> cache;
  ElementSupport es;
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
        // E = B (x) I3: node-major element DOFs from control DOFs.
        Eigen::MatrixXd ex = Eigen::MatrixXd::Zero(3 * n, 3 * s);
        for (int i = 0; i < n; ++i)
          for (int a = 0; a < s; ++a)
            for (int c = 0; c < 3; ++c) ex(3 * i + c, 3 * a + c) = b(i, a);
        const Eigen::MatrixXd& k = corotational->K(kind, block.group[e]);
        it = cache.emplace(es.key, Eigen::MatrixXd(ex.transpose() * k * ex)).first;
      }
      const Eigen::MatrixXd& tk = it->second;
      for (int a = 0; a < 3 * s; ++a) {
        for (int c = 0; c < 3 * s; ++c) {
          if (tk(a, c) != 0) t.emplace_back(3 * support[a / 3] + a % 3, 3 * support[c / 3] + c % 3, tk(a, c));
        }
      }
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
  const Points nodes = d_.node_matrix * p;
  std::vector<double> shape;
  for (const MaterialLocation& m : im.traced) {
    im.ShapeAt(m, shape);
    const int32_t* ids = im.layout.blocks[m.kind].element_nodes(m.element);
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (size_t k = 0; k < shape.size(); ++k) x += shape[k] * nodes.row(ids[k]).transpose();
    out.push_back(x);
  }
  return out;
}

Points Solid::ApplyMass(const Points& x) const { return impl_->mt * x; }

Points Solid::NodePositions() const { return d_.node_matrix * p_; }

Energies Solid::ComputeEnergies() const {
  const Impl& im = *impl_;
  Energies e;
  const Points v = (p_ - p_prev_) / im.h_sub;
  const Points mv = im.mt * v;
  e.kinetic = 0.5 * (v.array() * mv.array()).sum();
  e.strain = im.last_strain_energy;
  return e;
}

std::vector<Eigen::Vector3d> Solid::TracedPositions() const { return TracedPositionsAt(p_); }

}  // namespace dynsolid::solid
