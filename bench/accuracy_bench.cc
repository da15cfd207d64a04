// Accuracy against run time (bench/reports/accuracy.md): a cantilever
// under a tip load (static tip deflection against Timoshenko beam theory),
// a bar in tension (end displacement against F L / E A) and a vibrating
// cantilever (first bending frequency against Euler-Bernoulli), for both
// models, over subdivision levels x integrator x CG tolerance x time step,
// and central difference with a lumped mass at the default settings
// (integrator "central_difference_lumped"). CSV on stdout, one row per
// problem and configuration:
//
//   problem,model,levels,integrator,cg_tolerance,time_step,substeps,value,
//   analytic,error_percent,wall_per_sim_s,simulated_s,wall_s,cg_per_step,
//   static_method,static_wall_s,static_nonlinear,static_residual
//
// Static problems: the value is the configuration's linear static answer
// about rest, as beam theory is linear: for the corotational model its
// linear static solve (K0 u = F); for the local-frame model, which has no
// assembled stiffness, K0 by central differences of the control forces
// A^T g(A p) at rest on the free control DOFs (2 x 261 force evaluations),
// then the same solve. static_nonlinear is each model's own equilibrium
// (Newton with a finite-difference tangent from the linear answer, up to
// --newton_max_level), static_residual its relative force residual
// |F - A^T g| / |F| on the free control points. Neither depends on integrator,
// step or CG tolerance (at an equilibrium the step equations of both
// integrators hold exactly), only on model and levels; the cost column
// (wall_per_sim_s: wall seconds per simulated second of stepping that
// configuration under the same load, from rest, for --cost_seconds) is per
// configuration. The vibration run releases the beam from the corotational
// static shape under a small tip load, undamped, and times the zero
// crossings of the tip over --periods first-mode periods of the model.
//
// Progress and skipped combinations go to stderr.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Dense>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/strings/str_format.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"

ABSL_FLAG(int, max_levels, 3, "Highest subdivision level (0-3)");
ABSL_FLAG(double, periods, 1.3,
          "Vibration run length in first-mode periods of the model, estimated from its static "
          "stiffness (>= 1.25 gives three zero crossings)");
ABSL_FLAG(double, cost_seconds, 0.05,
          "Simulated seconds stepped to time a configuration on a static problem");
ABSL_FLAG(int, newton_max_level, 2,
          "Nonlinear equilibria (Newton with a finite-difference tangent) up to this level");
ABSL_FLAG(bool, statics_only, false, "Only the static answers (stderr), no stepping");
ABSL_FLAG(bool, full, false,
          "Every combination at every level (hours) instead of the limited set at levels 2-3");

namespace {

using dynsolid::Points;
using dynsolid::solid::Solid;
using Clock = std::chrono::steady_clock;

constexpr double kL = 1.0, kW = 0.1, kE = 1e6, kNu = 0.3, kRho = 1000.0;
constexpr double kTipX = kL * (1 - 1e-9);
constexpr int kLoadPoints = 3;  // k x k point forces over the end face

double Since(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

struct Config {
  std::string model;       // COROTATIONAL, COROTATIONAL_CELLS (a frame per control cell), LOCAL_FRAME
  int levels = 0;
  std::string integrator;  // CENTRAL_DIFFERENCE, BACKWARD_EULER
  double tol = 1e-4;
  double h = 1e-3;
  bool frequency = true;  // also run the vibrating cantilever
  bool lumped = false;    // solver.mass: LUMPED (CSV integrator "<integrator>_lumped")
};


std::string Lower(const std::string& s) {
  std::string out = s;
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// The CSV's integrator column: the scheme, with "_lumped" for a lumped mass.
std::string IntegratorLabel(const Config& c) {
  return c.lumped ? Lower(c.integrator) + "_lumped" : Lower(c.integrator);
}

// The scene's solver.model (and corotation) for a Config's model.
std::string ModelFields(const std::string& model) {
  return model == "COROTATIONAL_CELLS" ? "COROTATIONAL corotation: CONTROL_CELL" : model;
}

// The bench beam: [0, 1] x [-0.05, 0.05]^2, 10 x 2 x 2 control cells, clamped
// at x = 0, the load spread over the end face by k x k point forces (each
// also a traced point, so that the load vector can be read back), the tip
// centre traced first.
std::string SceneText(const Config& c, double damping, const std::string& axis, double force,
                      double nu) {
  std::string loads, traced = absl::StrFormat("traced { name: \"tip\" position { x: %.17g } } ", kTipX);
  for (int i = 0; i < kLoadPoints; ++i) {
    for (int j = 0; j < kLoadPoints; ++j) {
      const double y = kW * (-0.4 + 0.4 * i), z = kW * (-0.4 + 0.4 * j);
      if (force != 0) {
        loads += absl::StrFormat(
            "point_forces { position { x: %.17g y: %.17g z: %.17g } force { %s: %.17g } } ", kTipX,
            y, z, axis, force / (kLoadPoints * kLoadPoints));
      }
      traced += absl::StrFormat("traced { name: \"f%d%d\" position { x: %.17g y: %.17g z: %.17g } } ",
                                i, j, kTipX, y, z);
    }
  }
  return absl::StrFormat(R"pb(
    name: "accuracy"
    mesh { beam { length: %g width: %g height: %g cells_along: 10 cells_across: 2 } }
    subdivision { levels: %d }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: %g poisson_ratio: %.17g density: %g damping: %.17g } }
    constraints { fixed { box { min { x: -1e-6 y: -1 z: -1 } max { x: 1e-6 y: 1 z: 1 } } } }
    loads { %s }
    %s
    solver { model: %s integrator: %s time_step: %.17g cg_tolerance: %.17g max_substeps: 100000 mass: %s }
  )pb", kL, kW, kW, c.levels, kE, nu, kRho, damping, loads, traced, ModelFields(c.model), c.integrator, c.h, c.tol,
      c.lumped ? "LUMPED" : "CONSISTENT");
}

std::unique_ptr<Solid> Make(const std::string& text) {
  auto scene = dynsolid::scene::ParseScene(text, "accuracy_bench");
  if (!scene.ok()) {
    std::fprintf(stderr, "scene: %s\n", std::string(scene.status().message()).c_str());
    return nullptr;
  }
  auto d = dynsolid::scene::BuildDiscretization(*scene, "", std::nullopt);
  if (!d.ok()) {
    std::fprintf(stderr, "discretization: %s\n", std::string(d.status().message()).c_str());
    return nullptr;
  }
  auto s = Solid::Create(*scene, *std::move(d));
  if (!s.ok()) {
    std::fprintf(stderr, "create: %s\n", std::string(s.status().message()).c_str());
    return nullptr;
  }
  return *std::move(s);
}

// The static problems.
struct Problem {
  const char* name;
  std::string axis;
  double force;
  double nu;
  double analytic;
  double Read(const Eigen::Vector3d& tip) const {
    return axis == "z" ? tip.z() : tip.x() - kTipX;
  }
};

// The external load on the control points, F = sum_k (N_k A)^T f_k, read
// from the traced load points (linear in p): column by column.
Points LoadVector(const Solid& s, const Problem& pr) {
  const Points zero = Points::Zero(s.control_positions().rows(), 3);
  const std::vector<Eigen::Vector3d> x0 = s.TracedPositionsAt(zero);
  Points f = zero, e = zero;
  const Eigen::Vector3d fk =
      (pr.axis == "z" ? Eigen::Vector3d(0, 0, 1) : Eigen::Vector3d(1, 0, 0)) *
      (pr.force / (kLoadPoints * kLoadPoints));
  for (Eigen::Index i = 0; i < f.rows(); ++i) {
    for (int c = 0; c < 3; ++c) {
      e(i, c) = 1;
      const std::vector<Eigen::Vector3d> x = s.TracedPositionsAt(e);
      e(i, c) = 0;
      for (size_t k = 1; k < x.size(); ++k) f(i, c) += fk.dot(x[k] - x0[k]);
    }
  }
  return f;
}

struct Static {
  bool ok = false;
  double value = 0;        // the reported answer: linear, about rest
  double nonlinear = 0;    // the model's own (nonlinear) equilibrium
  std::string method;
  double wall_s = 0;
  double residual = 0;     // relative force residual at the nonlinear equilibrium
};

// The tangent stiffness at p on the free control DOFs (3 i + c, i not
// fixed), by central differences of A^T g(A p): 2 force evaluations per DOF.
// Not symmetrized: the corotational force (frames held fixed in its
// derivative) is not an exact gradient away from rest.
Eigen::MatrixXd FdStiffness(Solid& s, const Points& p, const std::vector<int>& dofs) {
  const int n = static_cast<int>(dofs.size());
  Eigen::MatrixXd k(n, n);
  const double eps = 1e-7 * kL;
  Points q = p;
  for (int j = 0; j < n; ++j) {
    const int i = dofs[j] / 3, c = dofs[j] % 3;
    q(i, c) = p(i, c) + eps;
    const Points gp = s.InternalControlForces(q);
    q(i, c) = p(i, c) - eps;
    const Points gm = s.InternalControlForces(q);
    q(i, c) = p(i, c);
    for (int r = 0; r < n; ++r) k(r, j) = (gp(dofs[r] / 3, dofs[r] % 3) - gm(dofs[r] / 3, dofs[r] % 3)) / (2 * eps);
  }
  return k;
}

Eigen::VectorXd Gather(const Points& x, const std::vector<int>& dofs) {
  Eigen::VectorXd v(dofs.size());
  for (size_t j = 0; j < dofs.size(); ++j) v[j] = x(dofs[j] / 3, dofs[j] % 3);
  return v;
}

// Static answers through the public API only. Corotational: the linear
// static solve (value) and the nonlinear equilibrium by modified Newton
// (the linear K0 as the iteration matrix). Local frame (no assembled
// stiffness): K0 by central differences of the control forces at rest on
// the free DOFs (a few hundred), then the same two answers.
Static SolveStatic(const Problem& pr, const std::string& model, int levels, int max_newton) {
  Static out;
  const auto t0 = Clock::now();
  Config cfg{model, levels, "CENTRAL_DIFFERENCE", 1e-4, 1e-3};
  auto s = Make(SceneText(cfg, 0, pr.axis, pr.force, pr.nu));
  if (!s) return out;
  const Points rest = s->control_positions();
  std::vector<int> dofs;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    if (std::abs(rest(i, 0)) > 1e-6) {
      for (int c = 0; c < 3; ++c) dofs.push_back(static_cast<int>(3 * i + c));
    }
  }
  const Eigen::VectorXd f = Gather(LoadVector(*s, pr), dofs);
  Points p = rest;
  if (model != "LOCAL_FRAME") {
    auto lin = s->SolveStaticLinear();
    if (!lin.ok()) return out;
    p = *lin;
    out.method = "linear_solve";
  } else {
    const Eigen::MatrixXd k0 = FdStiffness(*s, rest, dofs);
    const Eigen::VectorXd u = Eigen::MatrixXd(0.5 * (k0 + k0.transpose())).ldlt().solve(f);
    for (size_t j = 0; j < dofs.size(); ++j) p(dofs[j] / 3, dofs[j] % 3) += u[j];
    out.method = "fd_stiffness_solve";
  }
  out.value = pr.Read(s->TracedPositionsAt(p)[0]);
  // Newton from the linear answer with the finite-difference tangent,
  // halving the step while the residual does not fall.
  auto residual = [&](const Points& q) -> Eigen::VectorXd { return f - Gather(s->InternalControlForces(q), dofs); };
  Eigen::VectorXd res = residual(p);
  double r = res.norm() / f.norm();
  for (int it = 0; it < max_newton && r > 1e-9 && std::isfinite(r); ++it) {
    const Eigen::VectorXd du = FdStiffness(*s, p, dofs).partialPivLu().solve(res);
    for (double a = 1; a > 1e-3; a *= 0.5) {
      Points q = p;
      for (size_t j = 0; j < dofs.size(); ++j) q(dofs[j] / 3, dofs[j] % 3) += a * du[j];
      const Eigen::VectorXd rq = residual(q);
      if (rq.norm() / f.norm() < r) {
        p = q;
        res = rq;
        r = rq.norm() / f.norm();
        break;
      }
    }
  }
  out.nonlinear = pr.Read(s->TracedPositionsAt(p)[0]);
  out.residual = r;
  out.wall_s = Since(t0);
  out.ok = std::isfinite(out.value);
  return out;
}

struct Cost {
  bool ok = false;
  double wall_per_sim = 0, sim = 0, wall = 0, cg_per_step = 0;
  int substeps = 0;
};

// Steps the configuration from `start` (rest when empty) for `seconds`;
// `each` sees the solid after every step.
template <typename F>
Cost Stepping(Solid& s, double seconds, F each) {
  Cost c;
  const int steps = std::max(1, static_cast<int>(std::llround(seconds / s.time_step())));
  int64_t cg = 0;
  const auto t0 = Clock::now();
  for (int i = 1; i <= steps; ++i) {
    if (!s.Step().ok()) {
      c.wall = Since(t0);
      return c;
    }
    cg += s.last_step().cg_iterations;
    each(i);
  }
  c.wall = Since(t0);
  c.sim = steps * s.time_step();
  c.wall_per_sim = c.wall / c.sim;
  c.cg_per_step = static_cast<double>(cg) / steps;
  c.substeps = s.build_report().substeps;
  c.ok = true;
  return c;
}

void Row(const std::string& problem, const Config& c, int substeps, double value, double analytic,
         const Cost& cost, const Static* st) {
  std::printf("%s,%s,%d,%s,%.0e,%.6g,%d,%.9g,%.9g,%.5f,%.6g,%.6g,%.4f,%.2f,%s,%.4f,%.9g,%.3g\n",
              problem.c_str(), Lower(c.model).c_str(), c.levels, IntegratorLabel(c).c_str(), c.tol,
              c.h, substeps, value, analytic, 100.0 * (value - analytic) / analytic,
              cost.wall_per_sim, cost.sim, cost.wall, cost.cg_per_step,
              st ? st->method.c_str() : "", st ? st->wall_s : 0.0, st ? st->nonlinear : 0.0,
              st ? st->residual : 0.0);
  std::fflush(stdout);
}

// Levels 0 and 1: every combination, except that the local-frame model
// (10-13 explicit sub-steps per millisecond) vibrates with CG 1e-4 only at
// level 0 and with the default settings (CG 1e-4, h = 1e-3) only at level 1.
// Level 2: the corotational model's central difference at the default
// settings, backward Euler vibrating at h >= 1e-2 only, the local-frame
// model at the default settings on the static problems only.
// Level 3: the corotational model, backward Euler, CG 1e-4, h = 1e-2 and
// 1/30 s. --full runs everything (hours).
std::vector<Config> Configs(int max_levels, bool full) {
  std::vector<Config> out;
  for (int levels = 0; levels <= max_levels; ++levels) {
    for (const std::string model : {"COROTATIONAL", "LOCAL_FRAME"}) {
      for (const std::string integrator : {"CENTRAL_DIFFERENCE", "BACKWARD_EULER"}) {
        if (integrator == "BACKWARD_EULER" && model != "COROTATIONAL") continue;  // not available
        const bool be = integrator == "BACKWARD_EULER";
        const std::vector<double> steps =
            be ? std::vector<double>{1e-3, 1e-2, 1.0 / 30} : std::vector<double>{1e-3, 2.5e-4};
        for (double tol : {1e-4, 1e-8}) {
          for (double h : steps) {
            Config c{model, levels, integrator, tol, h};
            const bool first = tol == 1e-4 && h == 1e-3;  // the default settings
            if (!full && levels == 0 && model == "LOCAL_FRAME" && tol != 1e-4) c.frequency = false;
            if (!full && levels == 1 && model == "LOCAL_FRAME" && !first) c.frequency = false;
            if (!full && levels == 2) {
              if (model == "COROTATIONAL" && !be && !first) continue;
              if (model == "COROTATIONAL" && be && h < 1e-2) c.frequency = false;
              if (model == "LOCAL_FRAME" && !first) continue;
              if (model == "LOCAL_FRAME") c.frequency = false;
            }
            if (!full && levels >= 3 && (model != "COROTATIONAL" || !be || tol != 1e-4 || h < 1e-2)) {
              continue;
            }
            out.push_back(c);
            // Central difference with a lumped mass at the default settings
            // (levels 0-2; the local-frame model's frequency to level 1).
            if (!be && first && levels <= 2) {
              Config lumped = c;
              lumped.lumped = true;
              lumped.frequency = model == "COROTATIONAL" || levels <= 1 || full;
              out.push_back(lumped);
            }
            // The corotational model with a frame per control cell
            // (solver.corotation CONTROL_CELL) where the element one runs:
            // central difference at the default settings (consistent and
            // lumped) and backward Euler at CG 1e-4, levels 0-2.
            if (model == "COROTATIONAL" && levels <= 2 && tol == 1e-4 &&
                (be ? h >= 1e-2 : h == 1e-3)) {
              Config cells = c;
              cells.model = "COROTATIONAL_CELLS";
              cells.frequency = true;
              out.push_back(cells);
              if (!be) {
                cells.lumped = true;
                out.push_back(cells);
              }
            }
          }
        }
      }
    }
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  const int max_levels = absl::GetFlag(FLAGS_max_levels);
  const double inertia = kW * kW * kW * kW / 12, area = kW * kW, g = kE / (2 * (1 + kNu));
  const double kappa = 10 * (1 + kNu) / (12 + 11 * kNu);  // square section (Cowper)
  const double f = -1.0;
  const double timoshenko = f * kL * kL * kL / (3 * kE * inertia) + f * kL / (kappa * g * area);
  // nu = 0 in a scene means the default 0.3: a tiny nu stands for zero.
  const std::vector<Problem> problems = {
      {"cantilever_static", "z", f, kNu, timoshenko},
      {"bar_static", "x", 1.0, 1e-9, 1.0 * kL / (kE * area)},
  };
  const double omega1 =
      1.8751040687 * 1.8751040687 * std::sqrt(kE * inertia / (kRho * area * std::pow(kL, 4)));
  const double freq = omega1 / (2 * M_PI);
  std::printf(
      "problem,model,levels,integrator,cg_tolerance,time_step,substeps,value,analytic,"
      "error_percent,wall_per_sim_s,simulated_s,wall_s,cg_per_step,static_method,static_wall_s,"
      "static_nonlinear,static_residual\n");
  std::map<std::tuple<std::string, std::string, int>, Static> statics;
  std::map<int, std::optional<Points>> shapes;  // vibration start per level
  for (const Config& c : Configs(max_levels, absl::GetFlag(FLAGS_full))) {
    std::fprintf(stderr, "%s level %d %s tol %.0e h %.4g\n", Lower(c.model).c_str(), c.levels,
                 IntegratorLabel(c).c_str(), c.tol, c.h);
    for (const Problem& pr : problems) {
      auto key = std::make_tuple(std::string(pr.name), c.model, c.levels);
      if (!statics.count(key)) {
        statics[key] = SolveStatic(pr, c.model, c.levels, c.levels <= absl::GetFlag(FLAGS_newton_max_level) ? 8 : 0);
        const Static& st = statics[key];
        std::fprintf(stderr, "  %s static (%s): %.6g, nonlinear %.6g (residual %.2g, %.1f s wall)\n",
                     pr.name, st.method.c_str(), st.value, st.nonlinear, st.residual, st.wall_s);
      }
      const Static& st = statics[key];
      if (!st.ok || absl::GetFlag(FLAGS_statics_only)) continue;
      auto s = Make(SceneText(c, 0, pr.axis, pr.force, pr.nu));
      if (!s) continue;
      const Cost cost = Stepping(*s, absl::GetFlag(FLAGS_cost_seconds), [](int) {});
      if (!cost.ok) {
        std::fprintf(stderr, "  %s: stepping failed\n", pr.name);
        continue;
      }
      Row(pr.name, c, cost.substeps, st.value, pr.analytic, cost, &st);
    }
    // Vibrating cantilever.
    if (!c.frequency || absl::GetFlag(FLAGS_statics_only)) continue;
    if (!shapes.count(c.levels)) {
      Config cor{"COROTATIONAL", c.levels, "CENTRAL_DIFFERENCE", 1e-4, 1e-3};
      auto shape_solid = Make(SceneText(cor, 0, "z", -0.1, kNu));
      std::optional<Points> shape;
      if (shape_solid) {
        auto p = shape_solid->SolveStaticLinear();
        if (p.ok()) shape = *p;
      }
      shapes[c.levels] = shape;
    }
    if (!shapes[c.levels]) continue;
    auto s = Make(SceneText(c, 0, "z", 0, kNu));
    if (!s) continue;
    s->SetAtRest(*shapes[c.levels]);
    // Zero crossings of the tip's z, up and down (linear interpolation).
    std::vector<double> crossings;
    double prev = s->TracedPositions()[0].z();
    const double h = s->time_step();
    // The model's own first-mode frequency, estimated from its static
    // stiffness against the Timoshenko beam's (f ~ sqrt(k)): the run length
    // and the spacing below which a crossing is ripple of higher modes.
    const Static& cant = statics[std::make_tuple(std::string("cantilever_static"), c.model, c.levels)];
    const double f_est = cant.ok ? freq * std::sqrt(std::abs(timoshenko / cant.value)) : freq;
    const Cost cost = Stepping(*s, absl::GetFlag(FLAGS_periods) / f_est, [&](int i) {
      const double z = s->TracedPositions()[0].z();
      if ((prev < 0) != (z < 0)) {
        const double t = (i - 1 + prev / (prev - z)) * h;
        if (crossings.empty() || t - crossings.back() > 0.25 / f_est) crossings.push_back(t);
      }
      prev = z;
    });
    if (!cost.ok || crossings.size() < 2) {
      std::fprintf(stderr, "  frequency: %s\n", cost.ok ? "fewer than two zero crossings" : "stepping failed");
      continue;
    }
    const double measured =
        (crossings.size() - 1) / (2 * (crossings.back() - crossings.front()));
    Row("cantilever_frequency", c, cost.substeps, measured, freq, cost, nullptr);
  }
  return 0;
}
