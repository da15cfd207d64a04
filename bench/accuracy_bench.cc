// Accuracy against run time (issue 4): a cantilever under a tip load
// (static deflection against Timoshenko), a bar in tension (against
// F L / E A) and a vibrating cantilever (first bending frequency against
// Euler-Bernoulli), swept over model x levels x integrator x CG tolerance x
// time step. Prints CSV rows (stdout) for the report generator:
//   case,model,levels,integrator,cg_tolerance,time_step,value,analytic,error_percent,wall_s,simulated_s
// Static answers: the corotational model by its linear static solve; the
// local-frame model (no assembled stiffness) by a damped run of
// `relax_seconds` simulated seconds, whose value is what it reached.
//
//   accuracy_bench [max_levels=2] [relax_seconds=2]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"

namespace {

using dynsolid::Points;
using dynsolid::solid::Solid;
using Clock = std::chrono::steady_clock;

constexpr double kL = 1.0, kW = 0.1, kE = 1e6, kNu = 0.3, kRho = 1000.0;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

std::string Scene(const std::string& model, const std::string& integrator, int levels, double h,
                  double tol, double damping, const std::string& load_axis, double force,
                  double nu) {
  std::string loads;
  if (force != 0) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        loads += absl::StrFormat(
            "point_forces { position { x: %.17g y: %.17g z: %.17g } force { %s: %.17g } } ",
            kL * (1 - 1e-9), kW * (-0.4 + 0.4 * i), kW * (-0.4 + 0.4 * j), load_axis, force / 9);
  }
  return absl::StrFormat(R"pb(
    name: "bench"
    mesh { beam { length: %g width: %g height: %g cells_along: 10 cells_across: 2 } }
    subdivision { levels: %d }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: %g poisson_ratio: %g density: %g damping: %g } }
    constraints { fixed { box { min { x: -1e-6 y: -1 z: -1 } max { x: 1e-6 y: 1 z: 1 } } } }
    loads { %s }
    traced { name: "tip" position { x: %.17g y: 0 z: 0 } }
    solver { model: %s integrator: %s time_step: %.17g cg_tolerance: %.17g max_substeps: 100000 }
  )pb", kL, kW, kW, levels, kE, nu, kRho, damping, loads, kL * (1 - 1e-9), model, integrator, h,
                         tol);
}

std::unique_ptr<Solid> Make(const std::string& text) {
  auto scene = dynsolid::scene::ParseScene(text, "bench");
  if (!scene.ok()) return nullptr;
  auto d = dynsolid::scene::BuildDiscretization(*scene, "", std::nullopt);
  if (!d.ok()) return nullptr;
  auto s = Solid::Create(*scene, *std::move(d));
  if (!s.ok()) {
    std::fprintf(stderr, "%s\n", std::string(s.status().message()).c_str());
    return nullptr;
  }
  return *std::move(s);
}

void Row(const char* c, const std::string& model, int levels, const std::string& integrator,
         double tol, double h, double value, double analytic, double wall, double sim) {
  std::printf("%s,%s,%d,%s,%.0e,%.3g,%.9g,%.9g,%.4f,%.4f,%.4f\n", c, model.c_str(), levels,
              integrator.c_str(), tol, h, value, analytic, 100.0 * (value - analytic) / analytic,
              wall, sim);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const int max_levels = argc > 1 ? std::atoi(argv[1]) : 2;
  const double relax = argc > 2 ? std::atof(argv[2]) : 2.0;
  const double inertia = kW * kW * kW * kW / 12, area = kW * kW, g = kE / (2 * (1 + kNu));
  const double kappa = 10 * (1 + kNu) / (12 + 11 * kNu);
  const double f = -1.0;
  const double timoshenko = f * kL * kL * kL / (3 * kE * inertia) + f * kL / (kappa * g * area);
  const double bar = 1.0 * kL / (kE * area);  // nu = 0 for the bar
  const double omega1 = 1.8751040687 * 1.8751040687 * std::sqrt(kE * inertia / (kRho * area * std::pow(kL, 4)));
  const double freq = omega1 / (2 * M_PI);
  std::printf("case,model,levels,integrator,cg_tolerance,time_step,value,analytic,error_percent,wall_s,simulated_s\n");
  for (int levels = 0; levels <= max_levels; ++levels) {
    for (const std::string model : {"COROTATIONAL", "LOCAL_FRAME"}) {
      const bool corot = model == "COROTATIONAL";
      // Static cantilever and bar.
      for (int which = 0; which < 2; ++which) {
        const char* name = which == 0 ? "cantilever_static" : "bar_static";
        const double analytic = which == 0 ? timoshenko : bar;
        const std::string axis = which == 0 ? "z" : "x";
        const double force = which == 0 ? f : 1.0;
        const double nu = which == 0 ? kNu : 0.0;
        const auto t0 = Clock::now();
        if (corot) {
          auto s = Make(Scene(model, "CENTRAL_DIFFERENCE", levels, 1e-3, 1e-4, 0, axis, force, nu));
          if (!s) continue;
          auto p = s->SolveStaticLinear();
          if (!p.ok()) continue;
          const Eigen::Vector3d tip = s->TracedPositionsAt(*p)[0];
          const double v = which == 0 ? tip.z() : tip.x() - kL * (1 - 1e-9);
          Row(name, "corotational", levels, "static", 0, 0, v, analytic, Seconds(t0), 0);
        } else {
          // Damped relaxation (about critical for the first bending mode).
          const double h = 1e-3;
          auto s = Make(Scene(model, "CENTRAL_DIFFERENCE", levels, h, 1e-4, 2 * kRho * omega1, axis,
                              force, nu));
          if (!s) continue;
          const int steps = static_cast<int>(relax / h);
          bool ok = true;
          for (int i = 0; i < steps && ok; ++i) ok = s->Step().ok();
          const Eigen::Vector3d tip = s->TracedPositions()[0];
          const double v = which == 0 ? tip.z() : tip.x() - kL * (1 - 1e-9);
          Row(name, "local_frame", levels, ok ? "relax_cd" : "relax_cd_failed", 1e-4, h, v, analytic,
              Seconds(t0), relax);
        }
      }
      // Vibrating cantilever: release from the corotational static shape.
      auto shape_solid = Make(Scene("COROTATIONAL", "CENTRAL_DIFFERENCE", levels, 1e-3, 1e-4, 0, "z",
                                    -0.1, kNu));
      if (!shape_solid) continue;
      auto shape = shape_solid->SolveStaticLinear();
      if (!shape.ok()) continue;
      for (const std::string integrator : {"CENTRAL_DIFFERENCE", "BACKWARD_EULER"}) {
        if (integrator == "BACKWARD_EULER" && !corot) continue;
        for (double tol : {1e-4, 1e-8}) {
          for (double h : {1e-3, 2.5e-4}) {
            auto s = Make(Scene(model, integrator, levels, h, tol, 0, "z", 0, kNu));
            if (!s) continue;
            s->SetAtRest(*shape);
            const auto t0 = Clock::now();
            // Count upward zero crossings of the tip's z over ~4 periods.
            const double sim = 4.0 / freq;
            const int steps = static_cast<int>(sim / h);
            std::vector<double> crossings;
            double prev = s->TracedPositions()[0].z();
            bool ok = true;
            for (int i = 1; i <= steps && ok; ++i) {
              ok = s->Step().ok();
              const double z = s->TracedPositions()[0].z();
              if (prev < 0 && z >= 0) crossings.push_back((i - 1 + (-prev) / (z - prev)) * h);
              prev = z;
            }
            double measured = 0;
            if (crossings.size() >= 2) {
              measured = (crossings.size() - 1) / (crossings.back() - crossings.front());
            }
            Row("cantilever_frequency", corot ? "corotational" : "local_frame", levels,
                integrator == "BACKWARD_EULER" ? "backward_euler" : "central_difference", tol, h,
                measured, freq, Seconds(t0), sim);
          }
        }
      }
    }
  }
  return 0;
}
