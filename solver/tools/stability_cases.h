// The stiff and extreme cases of the stability report (bench/reports/stability.md), and one
// runner that steps a case and keeps the energy account from outside the
// solver (public Solid API only). Shared by bench/stability_bench (the
// report, larger runs) and tests/accuracy/stability_test (small runs).
//
// Energy account of a run, joules, at the end of every scene step t:
//   H(t) = kinetic + strain + penalty springs - work of the constant loads
// with the work of point forces sum f . (x(t) - x(0)) at the loaded
// material points (traced) and the work of gravity g . sum_i m_i (p_i(t) -
// p_i(0)), m = Mt 1 (the control points' share of the mass). Without
// damping or numerical dissipation H stays at H(0); a stable scheme only
// loses it. The report's energy ratio is
//   1 + (max_t H(t) - H(0)) / max_t (kinetic + strain + springs)
// i.e. 1 plus the largest growth of H as a fraction of the largest
// mechanical energy seen (for a free body, max H / H(0)).
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/solid/solid.h"

namespace dynsolid::stability {

enum class Shape {
  kBlock,      // 2 x 1 x 1 unit cells, [0, 2] x [0, 1] x [0, 1] m
  kThinLayer,  // 3 x 1 x 1 cells along x, the middle one kThinLayer m thick
  kBeam,       // 2 m long, 0.5 x 0.5 m section centred on the x axis, 4 x 1 x 1 cells
  kLongBlock,  // 4 x 1 x 1 unit cells, [0, 4] x [0, 1] x [0, 1] m
};
inline constexpr double kThinLayer = 1e-3;

// Energy growth (as a fraction of the peak mechanical energy) above which a
// run counts as unstable: above round-off and CG-tolerance drift, far below
// what any instability produces.
inline constexpr double kEnergyTolerance = 1e-3;
// Growth of the largest H from the first half of a run to the second (as a
// fraction of the peak) above which the energy counts as still rising. A
// bounded oscillation (central difference's backward-difference kinetic
// energy oscillates by a few 1e-3) and the corotational force's own slow
// gain under the 180-degree twist (about 1 %: frames held fixed, not an
// exact gradient at 40 % shear) stay below it; an instability multiplies H.
inline constexpr double kGrowthTolerance = 2e-2;

struct PointLoad {
  Eigen::Vector3d position;  // rest position, m
  Eigen::Vector3d force;     // N
};

// One case: a small corotational solid (control mesh `shape`, `levels`
// MacCracken-Joy levels), its material, constraints, loads and step.
struct Case {
  std::string name;
  std::string what;  // one line for the report
  Shape shape = Shape::kBlock;
  int levels = 1;
  double young = 1e6;     // Pa
  double poisson = 0.3;
  double density = 1000;  // kg/m^3
  std::string regions;    // extra `regions { ... }` text inside materials
  bool fixed_end = true;  // control points at x = 0 fixed
  double penalty = 0;     // > 0: springs (N/m) to the rest positions at x = 0 instead
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // m/s^2
  std::vector<PointLoad> loads;
  Eigen::Vector3d spin = Eigen::Vector3d::Zero();  // initial rigid angular velocity, rad/s
  double twist = 0;  // radians at x = length: released at rest from a twist about the x axis, linear in x
  double h = 1e-3;   // scene time step, s
  double duration = 1;  // simulated seconds the report runs it for (capped in steps)
};

enum class Integrator { kCentralDifference, kBackwardEuler };
const char* Name(Integrator integrator);  // "central_difference", "backward_euler"

// The scene text (corotational model) and the built solid; for kThinLayer
// the generated block is reshaped before discretization.
std::string SceneText(const Case& c, Integrator integrator, int max_substeps);
absl::StatusOr<std::unique_ptr<solid::Solid>> Build(const Case& c, Integrator integrator,
                                                     int max_substeps);

// The control positions of `rest` twisted by `radians` * x / length about
// the axis y = y0, z = z0 (parallel to x).
Points Twisted(const Points& rest, double radians, double length, double y0, double z0);

struct Outcome {
  absl::Status create;        // Solid::Create's answer (a refusal for explicit steps when too stiff)
  absl::Status final_status;  // the last Step()'s answer (OK: every step ran)
  int steps = 0;              // asked for
  int steps_done = 0;
  bool always_finite = true;  // positions, traced points, energies after every step (also failed ones)
  double initial_energy = 0;  // H(0), J
  double peak_mechanical = 0; // max kinetic + strain + springs, J
  double energy_ratio = 0;    // see the top of this file
  double final_energy_ratio = 0;
  // Central difference run with one sub-step per step throughout: the
  // energy ratio with the central velocity (p_{n+1} - p_{n-1}) / 2h in the
  // kinetic energy instead of the solver's backward difference (p_n -
  // p_{n-1}) / h, whose kinetic energy is off by O(omega h). NaN otherwise.
  double central_energy_ratio = NAN;
  int64_t rollbacks = 0;
  int substeps_start = 0;     // explicit sub-steps per step chosen by Create
  int substeps_end = 0;       // after the guard's halvings
  double stable_step = 0;     // 2 / omega_max estimated by Create, s
  double min_volume_ratio = 1;    // smallest signed volume / rest volume of a level-L cell over the run (< 0: inverted)
  double max_displacement = 0;    // largest control-point distance from rest, m
  double wall_s = 0;              // build + steps
  std::vector<double> energy;     // H after each completed step, J
  // 1 + (max H over the second half of the steps - max H over the first
  // half) / peak: above 1 when the energy keeps growing (an instability),
  // about 1 or below for a bounded oscillation or a loss.
  double late_growth_ratio = 0;

  bool completed() const { return create.ok() && final_status.ok() && steps_done == steps; }
  // "refused" (Create said why), "stopped" (the guard gave up and said
  // why), "non-finite" (must never happen), "growing" (completed, energy
  // above H(0) + tolerance and still rising in the second half),
  // "bounded rise" (above H(0) + tolerance but not rising at the end),
  // judged on central_energy_ratio when there is one,
  // "stable after rollbacks", "stable".
  std::string Verdict() const;
};

struct RunOptions {
  int steps = 100;           // scene steps (fewer when a step fails)
  int max_substeps = 2000;   // solver.max_substeps: Create refuses explicit steps needing more
  int force_substeps = 0;    // > 0: SetSubstepsForTesting(this) after Create (stable-step probes)
};

// Builds the case and runs it.
Outcome RunCase(const Case& c, Integrator integrator, const RunOptions& options);

// The report's cases: Young's modulus 1e3..1e10, Poisson 0.499, penalty
// 1e9, an inverting load, a 10 rad/s free spin, a 180-degree twist, a
// near-degenerate cell layer, a 1e6 density ratio; `h` is each case's step
// (the report runs each at several steps).
std::vector<Case> Cases();

}  // namespace dynsolid::stability
