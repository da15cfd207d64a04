// Stability report data (bench/reports/stability.md): the stiff and
// extreme cases of solver/tools/stability_cases.h, each with both
// integrators at several time steps, and the largest stable step against
// Young's modulus. CSV on stdout.
//
//   stability_bench cases [scale=1] [max_steps=4000] [max_substeps=20000]
//     runs each case for scale x its duration (at most max_steps steps)
//     case,what,integrator,time_step,young_modulus,verdict,... one row per run
//   stability_bench stable_step [steps=200]
//     young_modulus,integrator,estimate_s,largest_stable_s,smallest_unstable_s,tested_max_s
//
// Central difference's largest stable step is measured: one sub-step per
// scene step forced (SetSubstepsForTesting(1), no halving allowed), the step
// bisected between a run that completes without rollback or energy growth
// and one that does not. Backward Euler's is the largest tested step that
// runs stably (a lower bound: it is meant to have none).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/str_replace.h"
#include "solver/tools/stability_cases.h"

namespace {

using dynsolid::stability::Case;
using dynsolid::stability::Integrator;
using dynsolid::stability::kEnergyTolerance;
using dynsolid::stability::Outcome;
using dynsolid::stability::RunOptions;

std::string Csv(std::string s) {
  s = absl::StrReplaceAll(s, {{"\"", "'"}, {"\n", " "}});
  return "\"" + s + "\"";
}

constexpr Integrator kIntegrators[] = {Integrator::kCentralDifference, Integrator::kBackwardEuler};

int CasesTable(double seconds, int max_steps, int max_substeps) {
  std::printf(
      "case,what,integrator,time_step,young_modulus,verdict,completed,steps_done,steps,"
      "simulated_s,energy_ratio,central_energy_ratio,final_energy_ratio,late_growth_ratio,rollbacks,substeps_start,substeps_end,"
      "stable_step_estimate,min_volume_ratio,max_displacement_m,wall_s,status\n");
  for (const Case& base : dynsolid::stability::Cases()) {
    for (double h : {1e-4, 1e-3, 1e-2, 1.0 / 30}) {
      Case c = base;
      c.h = h;
      const int steps =
          std::min(max_steps, static_cast<int>(std::ceil(seconds * c.duration / h - 1e-9)));
      for (Integrator integrator : kIntegrators) {
        RunOptions options;
        options.steps = steps;
        options.max_substeps = max_substeps;
        const Outcome o = RunCase(c, integrator, options);
        const absl::Status& st = o.create.ok() ? o.final_status : o.create;
        std::printf("%s,%s,%s,%.6g,%.3g,%s,%d,%d,%d,%.6g,%.9g,%.9g,%.9g,%.9g,%lld,%d,%d,%.6g,%.6g,%.6g,%.3f,%s\n",
                    c.name.c_str(), Csv(c.what).c_str(), Name(integrator), h, c.young,
                    o.Verdict().c_str(), o.completed() ? 1 : 0, o.steps_done,
                    o.steps, o.steps_done * h, o.energy_ratio, o.central_energy_ratio, o.final_energy_ratio, o.late_growth_ratio,
                    static_cast<long long>(o.rollbacks), o.substeps_start, o.substeps_end,
                    o.stable_step, o.min_volume_ratio, o.max_displacement, o.wall_s,
                    Csv(st.ok() ? "ok" : std::string(st.message())).c_str());
        std::fflush(stdout);
      }
    }
  }
  return 0;
}

bool StableAt(Case c, Integrator integrator, double h, int steps, double* estimate) {
  c.h = h;
  RunOptions options;
  options.steps = steps;
  options.max_substeps = 1;
  options.force_substeps = integrator == Integrator::kCentralDifference ? 1 : 0;
  // Create refuses explicit steps above 0.9 x its estimate when max_substeps
  // is 1; build with room and force one sub-step instead.
  if (integrator == Integrator::kCentralDifference) options.max_substeps = 1000000;
  const Outcome o = RunCase(c, integrator, options);
  if (estimate != nullptr) *estimate = o.stable_step;
  if (std::getenv("STABILITY_DEBUG") != nullptr) {
    std::fprintf(stderr, "%s %s h=%.4g: %s ratio %.6g central %.6g late %.6g rollbacks %lld: %s %s\n",
                 c.name.c_str(), Name(integrator), h, o.Verdict().c_str(), o.energy_ratio,
                 o.central_energy_ratio, o.late_growth_ratio, static_cast<long long>(o.rollbacks),
                 std::string(o.create.message()).c_str(), std::string(o.final_status.message()).c_str());
  }
  // Explicit: an instability grows from one half of the run to the next
  // (or trips the guard); backward Euler: no energy above H(0) at all.
  if (!o.completed() || o.rollbacks != 0 || !o.always_finite) return false;
  return integrator == Integrator::kCentralDifference
             ? o.late_growth_ratio <= 1 + dynsolid::stability::kGrowthTolerance
             : o.energy_ratio <= 1 + kEnergyTolerance;
}

int StableStepTable(int steps) {
  std::printf("young_modulus,integrator,estimate_s,largest_stable_s,smallest_unstable_s,tested_max_s\n");
  for (const Case& base : dynsolid::stability::Cases()) {
    if (base.name.rfind("young_", 0) != 0) continue;
    for (Integrator integrator : kIntegrators) {
      double estimate = 0, lo = 0, hi = INFINITY, tested_max = 0;
      if (integrator == Integrator::kCentralDifference) {
        // The estimate from a run at a small step, then a scan and bisection
        // in multiples of it.
        StableAt(base, integrator, 1e-6, 1, &estimate);
        for (double f : {0.25, 0.5, 0.8, 1.0, 1.25, 1.6, 2.0, 3.0, 5.0}) {
          const double h = f * estimate;
          tested_max = std::max(tested_max, h);
          if (StableAt(base, integrator, h, steps, nullptr)) {
            lo = h;
          } else {
            hi = h;
            break;
          }
        }
        for (int it = 0; it < 6 && std::isfinite(hi) && lo > 0; ++it) {
          const double mid = std::sqrt(lo * hi);
          if (StableAt(base, integrator, mid, steps, nullptr)) lo = mid; else hi = mid;
        }
      } else {
        for (double h : {1e-4, 1e-3, 1e-2, 1.0 / 30, 0.1, 0.3, 1.0}) {
          tested_max = h;
          if (StableAt(base, integrator, h, steps, &estimate)) {
            lo = h;
          } else {
            hi = std::min(hi, h);
          }
        }
      }
      std::printf("%.3g,%s,%.6g,%.6g,%.6g,%.6g\n", base.young, Name(integrator), estimate, lo, hi,
                  tested_max);
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "cases";
  if (mode == "cases") {
    return CasesTable(argc > 2 ? std::atof(argv[2]) : 1.0, argc > 3 ? std::atoi(argv[3]) : 4000,
                      argc > 4 ? std::atoi(argv[4]) : 20000);
  }
  if (mode == "stable_step") return StableStepTable(argc > 2 ? std::atoi(argv[2]) : 200);
  std::fprintf(stderr, "usage: stability_bench cases [seconds] [max_steps] [max_substeps] | stable_step [steps]\n");
  return 2;
}
