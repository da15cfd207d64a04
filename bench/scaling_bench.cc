// Scaling with the control mesh (bench/reports/scaling.md): an n^3-cell
// block of 3 m at level 0 ((n+1)^3 control points), corotational with a
// frame per control cell, E 1e5 Pa, nu 0.3, density 1000, mass-proportional damping 2/s,
// consistent mass, bottom face fixed, 20 kN sideways spread over the top
// face's control points, h = 1 ms. For each size and solver: build time,
// median ms per step (and its solve phase) after a warm-up, and the peak
// resident memory of the process so far (VmHWM: sizes run smallest first,
// so a row's peak is its own or a smaller one's), and the answer: the top
// face's mean x displacement after all 5 + steps steps (bench/vega/compare.sh
// sets it beside VegaFEM's).
//
//   scaling_bench [--sizes=8,12,16,24] [--steps=40] [--solvers=factored,cg,backward_euler]
//                 [--phases]
//
// Prints figures only; nothing here is a test (the bench smoke runs it tiny).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "bench/figures.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"

ABSL_FLAG(std::string, sizes, "8,12,16,24", "cells per side, comma-separated");
ABSL_FLAG(int, steps, 40, "measured steps per size and solver (after 5 warm-up steps)");
ABSL_FLAG(bool, phases, false, "after each row, the build's phases (ms) from the solid's report");
ABSL_FLAG(std::string, solvers, "factored,cg,backward_euler",
          "central differences with the factor (factored) or CG (cg), backward Euler");

namespace {

using dynsolid::bench::Median;
using dynsolid::bench::PeakRssMb;

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a) {
  return std::chrono::duration<double, std::milli>(Clock::now() - a).count();
}

std::string SceneText(int n, const std::string& solver) {
  const double size = 3.0, top = size, dx = size / n;
  std::string loads;
  // The top face's (n+1)^2 control points share 20 kN along x.
  const double share = 2e4 / ((n + 1) * (n + 1));
  // (Inset by a micrometre: a point on the solid's boundary is in it.)
  auto inside = [&](double x) { return std::clamp(x, 1e-6, size - 1e-6); };
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= n; ++j) {
      loads += absl::StrCat("point_forces { position { x: ", inside(i * dx), " y: ",
                            inside(j * dx), " z: ",
                            top * (1 - 1e-9), " } force { x: ", share, " } } ");
    }
  }
  const std::string integrator =
      solver == "backward_euler" ? "BACKWARD_EULER" : "CENTRAL_DIFFERENCE";
  const std::string solve = solver == "cg" ? "CG" : "FACTORED";
  return absl::StrCat(
      "name: \"block", n, "\" mesh { block { nx: ", n, " ny: ", n, " nz: ", n,
      " size { x: ", size, " y: ", size, " z: ", size, " } } } subdivision { levels: 0 } ",
      "materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 2000 } } ",
      "constraints { fixed { box { min { x: -1 y: -1 z: -1e-6 } max { x: 4 y: 4 z: 1e-6 } } } } ",
      "loads { ", loads, "} ",
      "solver { model: COROTATIONAL corotation: CONTROL_CELL integrator: ", integrator,
      " time_step: 1e-3 mass: CONSISTENT explicit_solve: ", solve, " }");
}

}  // namespace

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  const int steps = std::max(1, absl::GetFlag(FLAGS_steps));
  std::vector<int> sizes;
  for (absl::string_view s : absl::StrSplit(absl::GetFlag(FLAGS_sizes), ',')) {
    int n = 0;
    if (absl::SimpleAtoi(s, &n) && n > 0) sizes.push_back(n);
  }
  const std::vector<std::string> solvers = absl::StrSplit(absl::GetFlag(FLAGS_solvers), ',');
  std::printf("# Scaling: n^3-cell blocks at level 0, corotational (a frame per control cell), "
              "consistent mass, h = 1 ms, %d steps after 5 warm-up\n\n", steps);
  std::printf("| cells | DOFs | solver | build s | ms/step | solve ms/step | ms per simulated s | "
              "us/DOF/step | substeps | peak RSS MB | top dx mm |\n");
  std::printf("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  int failures = 0;
  for (int n : sizes) {
    for (const std::string& solver : solvers) {
      const auto t0 = Clock::now();
      auto scene = dynsolid::scene::ParseScene(SceneText(n, solver), "scaling");
      if (!scene.ok()) {
        std::printf("| %d^3 | | %s | failed: %s |\n", n, solver.c_str(),
                    std::string(scene.status().message()).c_str());
        ++failures;
        continue;
      }
      auto d = dynsolid::scene::BuildDiscretization(*scene, "", std::nullopt);
      const double d_ms = Ms(t0);
      auto s = d.ok() ? dynsolid::solid::Solid::Create(*scene, *std::move(d))
                      : absl::StatusOr<std::unique_ptr<dynsolid::solid::Solid>>(d.status());
      if (!s.ok()) {
        std::printf("| %d^3 | | %s | failed: %s |\n", n, solver.c_str(),
                    std::string(s.status().message()).c_str());
        ++failures;
        continue;
      }
      const double build_ms = Ms(t0);
      const double discretization_ms = d_ms;
      dynsolid::solid::Solid& solid = **s;
      const dynsolid::Points rest = solid.control_positions();
      std::vector<double> step_ms, solve_ms;
      bool ok = true;
      for (int i = 0; i < 5 + steps && ok; ++i) {
        const auto t1 = Clock::now();
        ok = solid.Step().ok();
        if (i >= 5) {
          step_ms.push_back(Ms(t1));
          solve_ms.push_back(solid.last_phases().solve);
        }
      }
      if (!ok) {
        std::printf("| %d^3 | | %s | failed: a step failed |\n", n, solver.c_str());
        ++failures;
        continue;
      }
      const int64_t dofs = 3 * solid.control_positions().rows();
      const double ms = Median(step_ms);
      double top_dx = 0;  // the top face's (n+1)^2 control points (z = 3 m at rest)
      int top = 0;
      for (Eigen::Index i = 0; i < rest.rows(); ++i) {
        if (std::abs(rest(i, 2) - 3.0) < 1e-9) {
          top_dx += solid.control_positions()(i, 0) - rest(i, 0);
          ++top;
        }
      }
      std::printf("| %d^3 | %lld | %s | %.2f | %.3f | %.3f | %.0f | %.3f | %d | %.0f | %.4f |\n",
                  n, static_cast<long long>(dofs), solver.c_str(), build_ms / 1000.0, ms,
                  Median(solve_ms), ms / solid.time_step(), 1000.0 * ms / dofs,
                  solid.build_report().substeps, PeakRssMb(), top > 0 ? 1000.0 * top_dx / top : 0.0);
      if (absl::GetFlag(FLAGS_phases)) {
        const auto& ph = solid.build_report().phases;
        std::printf("|   build phases (ms): parse and discretization %.0f, layout %.0f, model %.0f, "
                    "mass %.0f, surface %.0f, stable step %.0f, K0 %.0f, the rest %.0f |\n",
                    discretization_ms, ph.layout, ph.model, ph.mass, ph.surface, ph.stable_step,
                    ph.k0,
                    build_ms - discretization_ms - ph.layout - ph.model - ph.mass - ph.surface -
                        ph.stable_step - ph.k0);
      }
      std::fflush(stdout);
    }
  }
  return failures == 0 ? 0 : 1;
}
