// The solid in time: forces (internal, external, implicit), one step of the
// chosen integrator with its sub-steps and rollbacks (Advance, Step), the
// stable-step estimate, material location, the static linear solve and the
// energies.
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <optional>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include "absl/strings/str_cat.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"
#include "solver/common/worker_pool.h"
#include "solver/fem/node_rows.h"
#include "solver/integrators/backward_euler.h"
#include "solver/integrators/central_difference.h"
#include "solver/integrators/reduced_cholesky.h"
#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/models/local_frame.h"
#include "solver/models/measure.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/load_bounds.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {

void Solid::Impl::MakeElementBoxes(const models::ElementLayout& l) {
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = l.blocks[kind];
    std::vector<Eigen::AlignedBox3d>& boxes = element_boxes[kind];
    boxes.resize(block.size());
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      Eigen::Vector3d lo = rest_nodes.row(ids[0]), hi = lo;
      for (int i = 1; i < block.nodes; ++i) {
        lo = lo.cwiseMin(rest_nodes.row(ids[i]).transpose());
        hi = hi.cwiseMax(rest_nodes.row(ids[i]).transpose());
      }
      boxes[e] = Eigen::AlignedBox3d(lo, hi);
    }
  }
}

absl::StatusOr<MaterialLocation> Solid::Impl::Locate(const Eigen::Vector3d& x, bool snap) const {
  const Points& rest = rest_nodes;
  std::vector<double> n, dn;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
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

namespace {

// Mt^-1 on the free control points (the fixed rows of the answer are zero),
// for the stable-step estimate's Lanczos passes, factored once per
// estimate: up to 1024 control points Mt with its fixed rows and columns
// made the identity in a dense Cholesky (integrators::Preconditioner::
// kDirect; 239 points and 14k entries on the chair at 2 levels after a
// local subdivision: a quarter of the dense matrix, whose factor fills
// in), above that CHOLMOD's factor on the free rows (integrators::
// ReducedCholesky). Eigen's sparse LDL^T took half of a 12^3-cell block's
// build, and CG to 1e-10 on an incomplete Cholesky three quarters of a
// 16^3 one's (20 s). CG only where the factor fails.
class MassSolver {
 public:
  MassSolver(const SparseMatrix& mass, const std::vector<uint8_t>& fixed)
      : fixed_(fixed.empty() ? std::vector<uint8_t>(mass.rows(), 0) : fixed) {
    if (mass.rows() <= integrators::ColumnPreconditioner::kDenseRows) {
      exact_.Setup(mass, fixed_, integrators::Preconditioner::kDirect);
    }
    if (!exact_.exact()) factor_.Factor(mass, fixed_);
    // Not positive definite, or out of memory: CG says how far it gets.
    if (!exact_.exact() && !factor_.factored()) cg_.Setup(&mass, fixed_);
  }
  // x = Mt^-1 b on the free rows (b's fixed rows zero).
  void Solve(const Points& b, Points& x) {
    if (exact_.exact()) {
      exact_.Apply(b, x);
    } else if (factor_.factored()) {
      factor_.Solve(b, x);
    } else {
      x.setZero();
      cg_.Solve(b, x, 1e-10, 1000);
    }
  }

 private:
  std::vector<uint8_t> fixed_;
  integrators::ColumnPreconditioner exact_;
  integrators::ReducedCholesky factor_;
  integrators::ConjugateGradient cg_;
};

}  // namespace

// omega_max^2 = largest eigenvalue of Mt^-1 Kt on the free control points,
// by Lanczos in the Mt inner product with Kt v = A^T (g(d0 + eps A v) / eps)
// (g(d0) = 0) plus the penalty springs. The largest Ritz value of the
// tridiagonal T_k is a lower bound on lambda_max that rises with k (also in
// finite precision, Paige); it stops once the Ritz pair's residual
// beta_k |y_k| is below kRitzTolerance of it. On the built-in scenes this
// takes 8-32 element passes and lands 0-3.6 % above what 40 power
// iterations reached (which converge as (lambda_2/lambda_1)^k; Lanczos as
// Chebyshev polynomials do); at 1e-3 it lands within 1.3e-4 of where 1e-4
// does, with a fifth fewer passes.
double Solid::Impl::EstimateOmegaMax(models::InternalForceModel& m, const SparseMatrix& mass,
                                     const std::vector<uint8_t>& fixed_set, int* passes,
                                     const models::CellCorotation* cells,
                                     WorkerPool* cell_pool) const {
  constexpr int kMinSteps = 8, kMaxSteps = 40;
  constexpr double kRitzTolerance = 1e-3;
  const Points& rest = rest_nodes;
  const SparseMatrix& nm = d->node_matrix;
  const int32_t nc = static_cast<int32_t>(nm.cols());
  Points q(nc, 3), q_prev = Points::Zero(nc, 3), kq(nc, 3), w(nc, 3), mw(nc, 3);
  Points dn(nm.rows(), 3), gn(nm.rows(), 3);
  double scale = 0;
  for (int32_t i = 0; i < rest.rows(); ++i) scale = std::max(scale, rest.row(i).cwiseAbs().maxCoeff());
  const double eps = 1e-7 * std::max(scale, 1e-3);
  auto free_rows = [&](Points& x) {
    for (int32_t i = 0; i < nc; ++i) {
      if (fixed_set[i]) x.row(i).setZero();
    }
  };
  auto m_norm = [&](const Points& x) {
    mw.noalias() = mass * x;
    return std::sqrt(std::max((x.array() * mw.array()).sum(), 0.0));
  };
  // Deterministic start vector.
  for (int32_t i = 0; i < nc; ++i) {
    for (int c = 0; c < 3; ++c) q(i, c) = std::sin(1.0 + 7.0 * i + 3.0 * c);
  }
  free_rows(q);
  const double q_norm = m_norm(q);
  if (q_norm == 0) return 0;
  q /= q_norm;
  MassSolver solve_mass(mass, fixed_set);
  std::vector<double> alpha, beta;
  double lambda = 0;
  // The forces at rest: zero, unless clay has moved the elements' rest
  // shapes (plastic offsets per element), when the difference quotient
  // must take them off (g(rest) / eps would read as a huge stiffness).
  Points g_rest;
  if (cells == nullptr && plasticity != nullptr) {
    m.ResetFrames();
    m.ExactForces(rest, gn);
    if (gn.cwiseAbs().maxCoeff() > 0) g_rest = gn;
  }
  for (int k = 0; k < kMaxSteps; ++k) {
    if (cells != nullptr) {
      cells->ApplyRest(q, kq, cell_pool);  // the same K, in control space
    } else {
      dn = rest + eps * (nm * q);
      m.ResetFrames();
      m.ExactForces(dn, gn);
      if (g_rest.size() > 0) gn -= g_rest;
      kq.noalias() = nm.transpose() * gn;
      kq /= eps;
    }
    for (size_t s = 0; s < spring_point.size(); ++s) kq.row(spring_point[s]) += spring_k[s] * q.row(spring_point[s]);
    free_rows(kq);
    alpha.push_back((q.array() * kq.array()).sum());
    // w = Mt^-1 Kt q - alpha q - beta q_prev, once more M-orthogonalized
    // against q (local reorthogonalization).
    solve_mass.Solve(kq, w);
    w -= alpha.back() * q;
    if (k > 0) w -= beta.back() * q_prev;
    mw.noalias() = mass * q;
    w -= (w.array() * mw.array()).sum() * q;
    const double b = m_norm(w);
    // The largest Ritz value of T_k and its residual b |y_k|.
    const int n = static_cast<int>(alpha.size());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> tri;
    tri.computeFromTridiagonal(Eigen::Map<const Eigen::VectorXd>(alpha.data(), n),
                               Eigen::Map<const Eigen::VectorXd>(beta.data(), n - 1),
                               Eigen::ComputeEigenvectors);
    lambda = std::max(lambda, tri.eigenvalues()[n - 1]);
    const double residual = b * std::abs(tri.eigenvectors()(n - 1, n - 1));
    if (passes != nullptr) *passes = n;
    if (b == 0 || (n >= kMinSteps && residual <= kRitzTolerance * lambda)) break;
    beta.push_back(b);
    q_prev = q;
    q = w / b;
  }
  if (cells == nullptr) m.ResetFrames();
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

void Solid::Impl::ControlForces(const Points& p, const Points& prev, Points& out,
                                PhaseTimes& phases, Points& pressure) {
  auto t0 = Clock::now();
  if (cell_model != nullptr) {
    // Control space throughout: no node positions, no projection.
    last_strain_energy = cell_model->Forces(p, out);
    out = -out;
    ++element_passes;
    phases.nodes = phases.project = phases.measure = -1;
    phases.stiffness = MsSince(t0);
  } else {
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
  }
  if (loads.has_constant_force() || !spring_point.empty() || has_pressure || probe.active()) {
    t0 = Clock::now();
    if (loads.has_constant_force()) out += loads.constant_forces();
    probe.AddTo(out);
    for (size_t s = 0; s < spring_point.size(); ++s) {
      const int32_t i = spring_point[s];
      out.row(i) -= spring_k[s] * (p.row(i) - rest_control.row(i));
    }
    if (has_pressure) {
      PositionForces(p, prev, pressure);
      out += pressure;
    }
    phases.loads = MsSince(t0);
  }
}

void Solid::Impl::ImplicitForces(const Points& p, const Points& prev, Points& out,
                                 PhaseTimes& phases, Points& pressure, bool energy) {
  auto t0 = Clock::now();
  if (cell_model == nullptr) {
    ToNodes(p, nodes);
    phases.nodes = MsSince(t0);
  } else {
    phases.nodes = -1;  // control space
  }
  t0 = Clock::now();
  if (cell_model != nullptr) {
    // Control space: frames held at p for the next step (cell_corotation.h).
    if (energy) {
      last_strain_energy = cell_model->Forces(p, g_cells);
      ++element_passes;
    } else {
      cell_model->UpdateFrames(p);
      ++frame_passes;
    }
  } else if (energy) {
    last_strain_energy = model->Forces(nodes, g);  // frames and the exact energy
    ++element_passes;
  } else {
    corotational->UpdateFrames(nodes);
    ++frame_passes;
  }
  phases.measure = -1;
  phases.stiffness = MsSince(t0);
  phases.project = cell_model != nullptr ? -1 : 0;
  ExternalForces(p, prev, out, pressure, phases);
}

void Solid::Impl::ExternalForces(const Points& p, const Points& prev, Points& out,
                                 Points& pressure, PhaseTimes& phases) {
  const auto t0 = Clock::now();
  if (loads.has_constant_force()) {
    out = loads.constant_forces();
  } else {
    out.setZero(p.rows(), 3);
  }
  if (has_pressure) {
    PositionForces(p, prev, pressure);
    out += pressure;
  }
  probe.AddTo(out);
  loads_changed = false;
  if (loads.has_constant_force() || !spring_point.empty() || has_pressure || probe.active()) {
    phases.loads = MsSince(t0);
  }
}

absl::Status Solid::Impl::Advance(Points& p, Points& p_prev, StepStats& stats,
                                   PhaseTimes& out) {
  PhaseTimes sub, sum;
  // Phases a pass reports as absent (-1) stay absent unless another pass
  // has them: the deformation measure is the local-frame model's; the
  // per-cell corotation has no node positions and no projection.
  sum.stiffness = sum.solve = 0;
  if (loads.has_constant_force() || !spring_point.empty() || has_pressure || probe.active()) sum.loads = 0;
  auto accumulate = [](double& total, double t) {
    if (t >= 0) total = std::max(total, 0.0) + t;
  };
  auto add = [&](const PhaseTimes& t) {
    accumulate(sum.nodes, t.nodes);
    sum.stiffness += t.stiffness;
    accumulate(sum.measure, t.measure);
    accumulate(sum.project, t.project);
    if (sum.loads >= 0) sum.loads += t.loads;
  };
  // Forces at p (kept from the end of the last step unless a rollback or
  // the first step invalidated them), so that every state's strain energy
  // is checked in the step that produced it.
  if (!forces_valid) {
    if (Folded()) {
      ImplicitForces(p, p_prev, f, sub, f_press, /*energy=*/true);
    } else {
      ControlForces(p, p_prev, f, sub, f_press);
    }
    add(sub);
    forces_valid = true;
  } else if (Folded() && loads_changed) {
    ExternalForces(p, p_prev, f, f_press, sub);
    if (sub.loads >= 0) sum.loads += sub.loads;
  }
  if (ledger.rebase_requested()) RebaseLedger(p, p_prev);
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
    if (const absl::Status within = CheckExtent(rest_control, p_next); !within.ok()) {
      return absl::InternalError(absl::StrCat(within.message(), " at sub-step ", k));
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
      // (Clay flows in a pass that holds frames and has each cell's
      // displacement: the full force pass instead of frames alone.)
      if (plasticity != nullptr) plasticity->Arm(h_sub);
      ImplicitForces(p_next, p, f_next, sub, f_press_next, /*energy=*/plasticity != nullptr);
      last_strain_energy = strain;
    } else {
      if (plasticity != nullptr) plasticity->Arm(h_sub);
      ControlForces(p_next, p, f_next, sub, f_press_next);
    }
    if (plasticity != nullptr) plasticity->Disarm();
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
    if (loads.has_constant_force()) {
      ledger.AddWork((loads.constant_forces().array() * (p_next - p).array()).sum());
    }
    if (probe.active()) ledger.AddWork(probe.Work(p, p_next));
    // Follower pressure: trapezoidal work over the sub-step.
    if (has_pressure) {
      ledger.AddWork(0.5 * ((f_press + f_press_next).array() * (p_next - p).array()).sum());
    }
    RETURN_IF_ERROR(ledger.Close(kinetic + last_strain_energy + springs, k));
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

absl::Status Solid::Step() {
  Impl& im = *impl_;
  StepStats stats;
  im.backup_p = p_;
  im.backup_prev = p_prev_;
  const EnergyLedger::Values ledger_at_start = im.ledger.values();
  if (im.environment != nullptr) im.environment->Checkpoint();
  if (im.plasticity != nullptr) im.plasticity->Checkpoint();
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
    im.ledger.set_values(ledger_at_start);
    if (im.environment != nullptr) im.environment->Rollback();
    if (im.plasticity != nullptr) im.plasticity->Rollback();
    im.model->ResetFrames();
    im.forces_valid = false;
    ++stats.rollbacks;
    ++rollbacks_;
    if (attempt >= kMaxHalvings || im.substeps * 2 > im.settings.max_substeps()) {
      last_step_ = stats;
      return absl::FailedPreconditionError(absl::StrCat(
          "step ", steps_ + 1, " failed: ", st.message(), "; still unstable after ", attempt + 1,
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
    if (im.fixed[i]) p_.row(i) = im.loads.held_at().row(i);
  }
  p_prev_ = p_;
  im.model->ResetFrames();
  if (im.use_implicit) im.implicit.ResetWarmStart();
  im.forces_valid = false;
  im.ledger.Start(StrainEnergy(p_));
}

int Solid::threads() const { return impl_->pool->size(); }

Solid::PlasticStats Solid::plastic_stats() const {
  PlasticStats out;
  const material::Plasticity* pl = impl_->plasticity.get();
  if (pl == nullptr) return out;
  for (const material::FlowLaw& law : pl->laws()) {
    if (law.yield > 0) ++out.cells;
  }
  out.max_strain = pl->max_alpha();
  out.yielded = pl->yielded_cells();
  out.dissipation = pl->dissipation();
  return out;
}

Solid::ContactStats Solid::contact_stats() const {
  ContactStats out;
  if (const contact::ObstacleContact* env = impl_->environment.get()) {
    out.touching = static_cast<int32_t>(env->touches().size());
    out.max_depth = env->max_depth();
  }
  return out;
}

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
  if (im.cell_model != nullptr) {
    Points g;
    im.cell_model->ForcesAt(p, g);
    return g;
  }
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
  if (im.cell_model != nullptr) {
    Points g;
    return im.cell_model->ForcesAt(p, g);
  }
  const Points d = im.node_rows.Multiply(p);
  Points g(d.rows(), 3);
  const models::InternalForceModel::Frames frames = im.model->frames();  // as above
  im.model->ResetFrames();
  const double e = im.model->ExactForces(d, g);
  im.model->set_frames(frames);
  return e;
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
  if (im.loads.has_constant_force()) {
    for (int32_t i = 0; i < nc; ++i)
      for (int c = 0; c < 3; ++c) f[3 * i + c] = im.loads.constant_forces()(i, c);
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

}  // namespace dynsolid::solid
