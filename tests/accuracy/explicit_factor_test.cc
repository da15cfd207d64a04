// Central differences solve their constant matrix with a factor
// made once (solver.explicit_solve FACTORED, the default) instead of a CG a
// step. On the accuracy cases (solver/tools/stability_cases.h) and on a block
// large enough for the CG to run on its incomplete Cholesky preconditioner,
// the factored path gives the CG path's answer (CG to 1e-13), and the same
// bits for 1, 2 and 3 threads.
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "solver/tools/stability_cases.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::stability {
namespace {

struct Outcome {
  bool made = false;  // Create accepted the scene (explicit steps may be refused)
  Points rest, p;
  int64_t cg_iterations = 0;
};

Outcome Simulate(const std::string& text, SolverSettings::ExplicitSolve solve, int threads,
                 int steps) {
  Outcome run;
  auto scene = scene::ParseScene(text, "test");
  EXPECT_OK(scene);
  if (!scene.ok()) return run;
  scene->mutable_solver()->set_explicit_solve(solve);
  if (solve == SolverSettings::CG) scene->mutable_solver()->set_cg_tolerance(1e-13);
  auto d = scene::BuildDiscretization(*scene, "", std::nullopt);
  EXPECT_OK(d);
  if (!d.ok()) return run;
  auto s = solid::Solid::Create(*scene, *std::move(d), threads);
  if (!s.ok()) return run;  // refused (too stiff for explicit steps at this h): both alike
  run.made = true;
  run.rest = (*s)->control_positions();
  for (int i = 0; i < steps; ++i) {
    EXPECT_OK((*s)->Step());
    run.cg_iterations += (*s)->last_step().cg_iterations;
  }
  run.p = (*s)->control_positions();
  return run;
}

// max |p_a - p_b| over the largest displacement from rest (0 when neither moved).
double RelativeDifference(const Outcome& a, const Outcome& b) {
  const double moved = (b.p - b.rest).cwiseAbs().maxCoeff();
  const double apart = (a.p - b.p).cwiseAbs().maxCoeff();
  return apart == 0 ? 0 : apart / moved;
}

// The factored solve against the CG (to 1e-13). After one step the answers
// differ by the solves' rounding, scaled by the matrix's conditioning: about
// 1e-15 of the motion on the plain cases, 2.5e-8 with a 1e9 penalty spring and
// 6e-10 with a 1e6 density ratio, so the bound is 1e-7. Over many steps a
// large, soft motion amplifies any difference (the corotation's rotations
// depend on the positions): 3e-15 after one step grows to 4e-7 after 30 on
// the softest block (E = 1e3), so the bound there is 1e-6. A wrong solve
// differs by order one.
void ExpectSameAnswer(const std::string& name, const std::string& text, int steps) {
  const Outcome factored1 = Simulate(text, SolverSettings::FACTORED, 2, 1);
  const Outcome cg1 = Simulate(text, SolverSettings::CG, 2, 1);
  ASSERT_EQ(factored1.made, cg1.made) << name;
  if (!factored1.made) return;
  const double rel1 = RelativeDifference(factored1, cg1);

  const Outcome factored = Simulate(text, SolverSettings::FACTORED, 2, steps);
  const Outcome cg = Simulate(text, SolverSettings::CG, 2, steps);
  const double rel = RelativeDifference(factored, cg);
  std::printf("%s: factored against CG, 1 step: %.3g of the motion; %d steps (%lld CG "
              "iterations): %.3g\n",
              name.c_str(), rel1, steps, static_cast<long long>(cg.cg_iterations), rel);
  EXPECT_LT(rel1, 1e-7) << name << ": one step";
  EXPECT_EQ(factored.cg_iterations, 0) << name;
  if (cg.p != cg.rest) {
    EXPECT_GT(cg.cg_iterations, 0) << name;
  }
  EXPECT_LT(rel, 1e-6) << name;
}

// A 6^3-cell block (6 m) at level 0 (343 control points: the CG runs on its
// incomplete Cholesky preconditioner), bottom fixed, pushed sideways at the
// top, with mass-proportional damping (2/s).
std::string BlockScene() {
  return R"pb(
    mesh { block { nx: 6 ny: 6 nz: 6 } }
    subdivision { levels: 0 }
    materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 2000 } }
    constraints { fixed { box { min { x: -1 y: -1 z: -1e-6 } max { x: 7 y: 7 z: 1e-6 } } } }
    loads { point_forces { position { x: 3 y: 3 z: 5.999 } force { x: 2000 } } }
    solver { model: COROTATIONAL corotation: CONTROL_CELL }
  )pb";
}

TEST(ExplicitFactorTest, MatchesTheCgOnTheAccuracyCases) {
  for (const Case& c : Cases()) {
    if (c.shape == Shape::kThinLayer) continue;  // reshaped before discretization (Build)
    ExpectSameAnswer(c.name, SceneText(c, Integrator::kCentralDifference, /*max_substeps=*/64),
                     30);
  }
}

TEST(ExplicitFactorTest, MatchesTheCgOnABlockBeyondTheExactPreconditioner) {
  ExpectSameAnswer("block 6^3", BlockScene(), 100);
}

TEST(ExplicitFactorTest, SameBitsForAnyThreadCount) {
  const Outcome one = Simulate(BlockScene(), SolverSettings::FACTORED, 1, 50);
  ASSERT_TRUE(one.made);
  EXPECT_GT((one.p - one.rest).cwiseAbs().maxCoeff(), 1e-6);  // it moved
  for (int threads : {2, 3}) {
    const Outcome other = Simulate(BlockScene(), SolverSettings::FACTORED, threads, 50);
    ASSERT_TRUE(other.made);
    EXPECT_TRUE(other.p == one.p) << threads << " threads";
  }
}

}  // namespace
}  // namespace dynsolid::stability
