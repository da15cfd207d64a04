// The implicit speed target: block3 with the corotational model and
// backward Euler, at least 200 steps per second on this machine, with the
// CG iteration counts printed. Measured on a block that MOVES (a block at
// rest costs no CG iteration and says nothing about the implicit solve):
//
//   static  the scene as is: no load, the block sits still (for comparison);
//   pull    a sideways point force at the top centre (switched on at t = 0):
//           the block bends over and swings about the bent shape;
//   twist   released from rest twisted about its vertical axis (the top
//           turned by --twist_degrees, linearly in height; the fixed bottom
//           face stays): a large-rotation torsional swing;
//   orbit   the pull force's direction turns about the vertical axis once
//           per --orbit_period seconds: the top circles, the element frames
//           never settle (a new load every step through RemoveLoad /
//           AddPointForce, as a sculpting client would drive it).
//
// Each case runs --warmup steps, then --steps measured steps, and prints the
// median and 90th percentile wall time per step, steps per second (1000 /
// median), the process CPU time per step (all threads; steadier than wall
// time on a shared machine), CG iterations per step (mean, max), element
// product passes and frame-only passes per step (StepStats), the median of
// each phase of Solid::last_phases(), and how far the traced top point moved
// (so a reader can see the motion was real). --two_pass runs the unfolded
// right-hand side (F, then a Kt product; Solid's reference path) for an A/B
// in one binary. The thread count is DYNSOLID_THREADS (set to 2 here when
// unset). Prints; never asserts on time.
//
//   implicit_bench [--scene block3] [--steps 1000] [--warmup 200] [--two_pass]
//                  [--cases static,pull,twist,orbit]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include <time.h>

#include <Eigen/Core>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "solver/common/stats.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"

ABSL_FLAG(std::string, scene, "block3", "built-in scene name or .textproto path");
ABSL_FLAG(int, steps, 1000, "measured steps per case");
ABSL_FLAG(int, warmup, 200, "steps before measuring");
ABSL_FLAG(double, force, 1e5, "pull: sideways force at the top centre, newtons");
ABSL_FLAG(double, twist_degrees, 60, "twist: initial turn of the top about the vertical axis");
ABSL_FLAG(double, orbit_period, 0.5, "orbit: seconds per turn of the force's direction");
ABSL_FLAG(bool, two_pass, false,
          "backward Euler's unfolded right-hand side (F, then a Kt product): the reference "
          "path Solid keeps for tests, for an A/B in one binary");
ABSL_FLAG(std::string, cases, "static,pull,twist,orbit", "comma-separated cases to run");
ABSL_FLAG(std::string, corotation, "element",
          "element: a frame per finite element (docs/model.md 4b); cells: a frame per control cell "
          "(solver.corotation CONTROL_CELL, models/cell_corotation.h)");

namespace {

using Clock = std::chrono::steady_clock;
using dynsolid::solid::PhaseTimes;
using dynsolid::solid::Solid;

// Process CPU time (all threads), milliseconds: less sensitive than wall
// time to other jobs on a shared machine (it includes the pool's brief spins).
double CpuMs() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * ts.tv_sec + 1e-6 * ts.tv_nsec;
}

// Median of a phase over the measured steps; -1 (absent) stays -1.
double PhaseMedian(const std::vector<PhaseTimes>& phases, double PhaseTimes::*field) {
  std::vector<double> v;
  for (const PhaseTimes& p : phases) v.push_back(p.*field);
  return dynsolid::Median(v);
}

std::string Fmt(double ms) {
  if (ms < 0) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", ms);
  return buf;
}

struct Case {
  std::string name;
  bool ok = false;
  std::string error;
  double median = 0, p90 = 0, mean = 0, cpu = 0;
  double cg_mean = 0, passes_mean = 0, frame_passes_mean = 0;
  int cg_max = 0, cg_min = 0;
  double top_max_disp = 0, top_path = 0;
  double residual_max = 0;
  int64_t rollbacks = 0;
  int64_t rechecks = 0;  // warm starts checked against the exact right-hand side
  PhaseTimes phase;
};

dynsolid::PointForce Pull(const Eigen::Vector3d& at, const Eigen::Vector3d& f) {
  dynsolid::PointForce pf;
  pf.mutable_position()->set_x(at.x());
  pf.mutable_position()->set_y(at.y());
  pf.mutable_position()->set_z(at.z());
  pf.mutable_force()->set_x(f.x());
  pf.mutable_force()->set_y(f.y());
  pf.mutable_force()->set_z(f.z());
  return pf;
}

Case Run(const std::string& name, const dynsolid::Scene& scene) {
  Case c;
  c.name = name;
  auto d = dynsolid::scene::BuildDiscretization(scene, dynsolid::scene::BuiltinSceneDir(),
                                                std::nullopt);
  if (!d.ok()) {
    c.error = std::string(d.status().message());
    return c;
  }
  auto made = Solid::Create(scene, *std::move(d));
  if (!made.ok()) {
    c.error = std::string(made.status().message());
    return c;
  }
  Solid& s = **made;
  if (absl::GetFlag(FLAGS_two_pass)) s.SetImplicitTwoPassForTesting(true);
  // The top centre (just below the top face, inside the solid) and the
  // vertical axis through it.
  const dynsolid::Points& rest = s.control_positions();
  const Eigen::Vector3d lo = rest.colwise().minCoeff().transpose();
  const Eigen::Vector3d hi = rest.colwise().maxCoeff().transpose();
  const Eigen::Vector3d top(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()),
                            hi.z() - 0.02 * (hi.z() - lo.z()));
  const double force = absl::GetFlag(FLAGS_force);
  int64_t orbit_id = -1;
  const double orbit_period = absl::GetFlag(FLAGS_orbit_period);
  auto orbit_force = [&](double t) {
    const double a = 2 * M_PI * t / orbit_period;
    return Pull(top, force * Eigen::Vector3d(std::cos(a), std::sin(a), 0));
  };
  if (name == "pull") {
    auto id = s.AddPointForce(Pull(top, Eigen::Vector3d(force, 0, 0)));
    if (!id.ok()) {
      c.error = std::string(id.status().message());
      return c;
    }
  } else if (name == "orbit") {
    auto id = s.AddPointForce(orbit_force(0));
    if (!id.ok()) {
      c.error = std::string(id.status().message());
      return c;
    }
    orbit_id = *id;
  } else if (name == "twist") {
    // Turn each control point about the vertical axis by an angle growing
    // linearly from 0 at the bottom to twist_degrees at the top.
    dynsolid::Points p = rest;
    const double full = absl::GetFlag(FLAGS_twist_degrees) * M_PI / 180;
    for (int64_t i = 0; i < p.rows(); ++i) {
      const double a = full * (p(i, 2) - lo.z()) / (hi.z() - lo.z());
      const double x = p(i, 0) - top.x(), y = p(i, 1) - top.y();
      p(i, 0) = top.x() + std::cos(a) * x - std::sin(a) * y;
      p(i, 1) = top.y() + std::sin(a) * x + std::cos(a) * y;
    }
    s.SetAtRest(p);
  } else if (name != "static") {
    c.error = "unknown case";
    return c;
  }
  const Eigen::Vector3d top0 = s.TracedPositions().empty() ? Eigen::Vector3d::Zero()
                                                            : s.TracedPositions()[0];
  Eigen::Vector3d top_prev = top0;
  const int warmup = absl::GetFlag(FLAGS_warmup), steps = absl::GetFlag(FLAGS_steps);
  std::vector<double> ms, cg, passes, frame_passes;
  std::vector<PhaseTimes> phases;
  double cpu0 = 0;
  for (int i = 0; i < warmup + steps; ++i) {
    if (i == warmup) cpu0 = CpuMs();
    if (orbit_id >= 0) {
      // A new direction each step, applied between steps like a live edit.
      if (!s.RemoveLoad(orbit_id).ok()) {
        c.error = "RemoveLoad failed";
        return c;
      }
      auto id = s.AddPointForce(orbit_force(s.time()));
      if (!id.ok()) {
        c.error = std::string(id.status().message());
        return c;
      }
      orbit_id = *id;
    }
    const auto t0 = Clock::now();
    const absl::Status st = s.Step();
    const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!st.ok()) {
      c.error = std::string(st.message());
      return c;
    }
    c.rollbacks += s.last_step().rollbacks;
    if (!s.TracedPositions().empty()) {
      const Eigen::Vector3d t = s.TracedPositions()[0];
      c.top_max_disp = std::max(c.top_max_disp, (t - top0).norm());
      if (i >= warmup) c.top_path += (t - top_prev).norm();
      top_prev = t;
    }
    if (i < warmup) continue;
    ms.push_back(dt);
    cg.push_back(s.last_step().cg_iterations);
    passes.push_back(s.last_step().element_passes);
    frame_passes.push_back(s.last_step().frame_passes);
    c.rechecks += s.last_step().warm_start_rechecks;
    c.residual_max = std::max(c.residual_max, s.last_step().cg_relative_residual);
    phases.push_back(s.last_phases());
  }
  c.cpu = (CpuMs() - cpu0) / steps;
  c.median = dynsolid::Median(ms);
  c.p90 = dynsolid::Percentile(ms, 0.9);
  c.mean = std::accumulate(ms.begin(), ms.end(), 0.0) / ms.size();
  c.cg_mean = std::accumulate(cg.begin(), cg.end(), 0.0) / cg.size();
  c.passes_mean = std::accumulate(passes.begin(), passes.end(), 0.0) / passes.size();
  c.frame_passes_mean =
      std::accumulate(frame_passes.begin(), frame_passes.end(), 0.0) / frame_passes.size();
  c.cg_max = static_cast<int>(*std::max_element(cg.begin(), cg.end()));
  c.cg_min = static_cast<int>(*std::min_element(cg.begin(), cg.end()));
  c.phase.nodes = PhaseMedian(phases, &PhaseTimes::nodes);
  c.phase.measure = PhaseMedian(phases, &PhaseTimes::measure);
  c.phase.stiffness = PhaseMedian(phases, &PhaseTimes::stiffness);
  c.phase.project = PhaseMedian(phases, &PhaseTimes::project);
  c.phase.loads = PhaseMedian(phases, &PhaseTimes::loads);
  c.phase.damping = PhaseMedian(phases, &PhaseTimes::damping);
  c.phase.solve = PhaseMedian(phases, &PhaseTimes::solve);
  c.ok = true;
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  setenv("DYNSOLID_THREADS", "2", /*overwrite=*/0);
  auto loaded = dynsolid::scene::LoadSceneOrMesh(absl::GetFlag(FLAGS_scene));
  if (!loaded.ok()) {
    std::fprintf(stderr, "%s\n", std::string(loaded.status().message()).c_str());
    return 2;
  }
  dynsolid::Scene scene = loaded->scene;
  scene.mutable_solver()->set_model(dynsolid::SolverSettings::COROTATIONAL);
  scene.mutable_solver()->set_integrator(dynsolid::SolverSettings::BACKWARD_EULER);
  const bool cells = absl::GetFlag(FLAGS_corotation) == "cells";
  scene.mutable_solver()->set_corotation(cells ? dynsolid::SolverSettings::CONTROL_CELL
                                               : dynsolid::SolverSettings::ELEMENT);
  const dynsolid::SolverSettings settings = dynsolid::scene::ResolvedSolverSettings(scene);
  std::printf("# %s, corotational model (a frame per %s), backward Euler (%s right-hand side), "
              "h = %g s, CG tolerance %g, %s threads, %d warm-up + %d measured steps\n\n",
              scene.name().c_str(), cells ? "control cell" : "element",
              absl::GetFlag(FLAGS_two_pass) ? "two-pass" : "folded",
              settings.time_step(), settings.cg_tolerance(),
              std::getenv("DYNSOLID_THREADS"), absl::GetFlag(FLAGS_warmup),
              absl::GetFlag(FLAGS_steps));
  std::printf("| case | median ms/step | p90 ms/step | steps/s | CPU ms/step | CG it/step mean | "
              "max | element passes/step | frame passes/step | max rel. residual | "
              "top moved max m | top path m | rollbacks | warm-start rechecks |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
              "| ---: | ---: |\n");
  std::vector<Case> done;
  std::string list = absl::GetFlag(FLAGS_cases);
  for (size_t start = 0; start <= list.size();) {
    size_t end = list.find(',', start);
    if (end == std::string::npos) end = list.size();
    const std::string name = list.substr(start, end - start);
    start = end + 1;
    if (name.empty()) continue;
    const Case c = Run(name, scene);
    if (!c.ok) {
      std::printf("| %s | failed: %s |\n", name.c_str(), c.error.c_str());
      continue;
    }
    std::printf("| %s | %.3f | %.3f | %.0f | %.3f | %.2f | %d | %.2f | %.2f | %.1e | %.3f | %.3f "
                "| %lld | %lld |\n",
                c.name.c_str(), c.median, c.p90, 1000.0 / c.median, c.cpu, c.cg_mean, c.cg_max,
                c.passes_mean, c.frame_passes_mean,
                c.residual_max, c.top_max_disp, c.top_path, static_cast<long long>(c.rollbacks),
                static_cast<long long>(c.rechecks));
    std::fflush(stdout);
    done.push_back(c);
  }
  std::printf("\n# Phases, median ms over the measured steps (- = absent)\n\n");
  std::printf("| case | nodes | stiffness | project | loads | solve |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: |\n");
  for (const Case& c : done) {
    std::printf("| %s | %s | %s | %s | %s | %s |\n", c.name.c_str(), Fmt(c.phase.nodes).c_str(),
                Fmt(c.phase.stiffness).c_str(), Fmt(c.phase.project).c_str(),
                Fmt(c.phase.loads).c_str(), Fmt(c.phase.solve).c_str());
  }
  return 0;
}
