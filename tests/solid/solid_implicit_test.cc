// Backward Euler's folded right-hand side (Solid's default implicit path:
// F - h Kt v as one element pass at p + h v with the frames of p) against the
// two-pass reference (F at p, then a Kt product): the same trajectory to the
// CG tolerance, the strain energy carried by the step against the exact one,
// no rollback, and the same bits for any thread count. The block bends under
// a sideways pull at its top while released from a twist, so the frames turn
// and CG works every step.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

std::string BlockScene(double cg_tolerance) {
  return absl::StrCat(R"pb(
    name: "block"
    mesh { block { nx: 2 ny: 2 nz: 3 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 500 } }
    constraints { fixed { box { min { x: -0.01 y: -0.01 z: -0.01 } max { x: 2.01 y: 2.01 z: 0.01 } } } }
    solver { model: COROTATIONAL integrator: BACKWARD_EULER time_step: 2e-3 cg_tolerance: )pb",
                      cg_tolerance, " }\n");
}

// A solid of `text`, twisted 50 degrees at the top (linearly in height) and
// released, with 4e4 N pulling its top sideways.
std::unique_ptr<Solid> Make(const std::string& text) {
  auto scene = scene::ParseScene(text, "test");
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(), std::nullopt);
  EXPECT_OK(d);
  auto made = Solid::Create(*scene, *std::move(d));
  EXPECT_OK(made);
  if (!made.ok()) return nullptr;
  std::unique_ptr<Solid> s = *std::move(made);
  Points p = s->control_positions();
  for (int64_t i = 0; i < p.rows(); ++i) {
    const double a = 0.87 * p(i, 2) / 3.0, x = p(i, 0) - 1, y = p(i, 1) - 1;
    p(i, 0) = 1 + std::cos(a) * x - std::sin(a) * y;
    p(i, 1) = 1 + std::sin(a) * x + std::cos(a) * y;
  }
  s->SetAtRest(p);
  PointForce pull;
  pull.mutable_position()->set_x(1);
  pull.mutable_position()->set_y(1);
  pull.mutable_position()->set_z(2.9);
  pull.mutable_force()->set_x(4e4);
  EXPECT_OK(s->AddPointForce(pull));
  return s;
}

struct Trajectory {
  std::vector<Points> p;
  std::vector<double> strain, exact_strain;
  int cg_iterations = 0;
};

Trajectory Advance(Solid& s, int steps) {
  Trajectory r;
  for (int i = 0; i < steps; ++i) {
    EXPECT_OK(s.Step());
    EXPECT_EQ(s.last_step().rollbacks, 0) << "step " << i;
    r.p.push_back(s.control_positions());
    r.strain.push_back(s.ComputeEnergies().strain);
    r.exact_strain.push_back(s.StrainEnergy(s.control_positions()));
    r.cg_iterations += s.last_step().cg_iterations;
  }
  return r;
}

// Largest deviation of a from b over the run, relative to b's largest
// displacement from `rest`.
double Deviation(const Trajectory& a, const Trajectory& b, const Points& rest) {
  double dev = 0, disp = 0;
  for (size_t i = 0; i < a.p.size(); ++i) {
    dev = std::max(dev, (a.p[i] - b.p[i]).cwiseAbs().maxCoeff());
    disp = std::max(disp, (b.p[i] - rest).cwiseAbs().maxCoeff());
  }
  return dev / disp;
}

// Two solids of `text`: the folded default and the two-pass reference.
struct Pair {
  std::unique_ptr<Solid> folded, two_pass;
};
Pair MakePair(const std::string& text) {
  Pair p{Make(text), Make(text)};
  EXPECT_NE(p.folded, nullptr);
  EXPECT_NE(p.two_pass, nullptr);
  if (p.two_pass != nullptr) p.two_pass->SetImplicitTwoPassForTesting(true);
  return p;
}

TEST(SolidImplicitTest, FoldedRhsFollowsTheTwoPassReferenceToTheCgTolerance) {
  constexpr int kSteps = 60;
  for (double tol : {1e-10, 1e-4}) {
    auto [folded, two_pass] = MakePair(BlockScene(tol));
    ASSERT_NE(folded, nullptr);
    ASSERT_NE(two_pass, nullptr);
    const Points rest = folded->control_positions();
    const Trajectory a = Advance(*folded, kSteps);
    const Trajectory b = Advance(*two_pass, kSteps);
    const double dev = Deviation(a, b, rest);
    // Worst relative gap between the carried energy (frames of the step's
    // start) and the exact one (the state's own frames), over the run.
    double e_gap = 0, e_max = 0;
    for (int i = 0; i < kSteps; ++i) {
      e_gap = std::max(e_gap, std::abs(a.strain[i] - a.exact_strain[i]));
      e_max = std::max(e_max, a.exact_strain[i]);
      EXPECT_NEAR(b.strain[i], b.exact_strain[i], 1e-9 * b.exact_strain[i])
          << "two-pass: the exact energy (frames warm-started or afresh), step " << i;
    }
    std::printf("tolerance %g: positions deviate %.2e of the displacement; CG iterations %d "
                "folded, %d two-pass; carried strain energy within %.2e of the peak %.3e J\n",
                tol, dev, a.cg_iterations, b.cg_iterations, e_gap / e_max, e_max);
    EXPECT_GT(a.cg_iterations, kSteps) << "CG must work: the test needs motion";
    // Per step the two solve the same system from right-hand sides equal to
    // rounding (measured: 1e-14 of the displacement, the same CG iteration
    // counts); the bounds leave room for an iteration count to differ.
    EXPECT_LT(dev, tol > 1e-6 ? 1e-6 : 1e-9) << "tolerance " << tol;
    EXPECT_LT(e_gap, 1e-3 * e_max) << "tolerance " << tol;
  }
}

// Single-precision CG products (the default at tolerance 1e-4) against
// double ones: the same CG iteration counts and a trajectory within a small
// fraction of the tolerance's own effect (measured: 1.4e-11 of the
// displacement, where tolerance 1e-4 against 1e-10 moves it 1.5e-5).
TEST(SolidImplicitTest, SinglePrecisionCgFollowsTheDoubleOne) {
  constexpr int kSteps = 60;
  const std::string text = BlockScene(1e-4);
  auto single = Make(text);
  auto twice = Make(text);
  auto exact = Make(BlockScene(1e-10));
  ASSERT_NE(single, nullptr);
  ASSERT_NE(twice, nullptr);
  ASSERT_NE(exact, nullptr);
  EXPECT_TRUE(single->build_report().single_precision_cg);
  EXPECT_FALSE(exact->build_report().single_precision_cg) << "1e-10 is below float's reach";
  twice->SetDoublePrecisionCgForTesting();
  EXPECT_FALSE(twice->build_report().single_precision_cg);
  const Points rest = single->control_positions();
  const Trajectory a = Advance(*single, kSteps);
  const Trajectory b = Advance(*twice, kSteps);
  const Trajectory c = Advance(*exact, kSteps);
  const double float_dev = Deviation(a, b, rest), tolerance_dev = Deviation(b, c, rest);
  std::printf("single against double products: %.2e of the displacement (CG iterations %d and "
              "%d); tolerance 1e-4 against 1e-10: %.2e\n",
              float_dev, a.cg_iterations, b.cg_iterations, tolerance_dev);
  EXPECT_LT(float_dev, 0.1 * tolerance_dev);
  EXPECT_LE(std::abs(a.cg_iterations - b.cg_iterations), 2);
  // The energy carried from the CG's own (float) products.
  for (int i = 0; i < kSteps; ++i) {
    EXPECT_NEAR(a.strain[i], b.strain[i], 1e-6 * b.exact_strain[i] + 1e-12) << "step " << i;
  }
}

// Loads edited between steps (a point force moved, gravity, a pressure):
// the folded path recomputes only the external forces (no element pass),
// the two-pass path all forces; the trajectories agree to rounding.
TEST(SolidImplicitTest, LoadEditsCostNoElementPassAndFollowTheReference) {
  auto [folded, two_pass] = MakePair(BlockScene(1e-10));
  ASSERT_NE(folded, nullptr);
  ASSERT_NE(two_pass, nullptr);
  const Points rest = folded->control_positions();
  Trajectory a, b;
  int64_t moving[2] = {-1, -1};
  for (int i = 0; i < 30; ++i) {
    Solid* solids[2] = {folded.get(), two_pass.get()};
    for (int k = 0; k < 2; ++k) {
      Solid& s = *solids[k];
      if (i % 3 == 0) {  // a force that turns every third step
        if (moving[k] >= 0) {
          ASSERT_OK(s.RemoveLoad(moving[k]));
        }
        PointForce pf;
        pf.mutable_position()->set_x(1.5);
        pf.mutable_position()->set_y(0.5);
        pf.mutable_position()->set_z(2.5);
        pf.mutable_force()->set_y(2e4 * std::cos(0.3 * i));
        pf.mutable_force()->set_z(2e4 * std::sin(0.3 * i));
        auto id = s.AddPointForce(pf);
        ASSERT_OK(id);
        moving[k] = *id;
      }
      if (i == 10) {
        Vec3 g;
        g.set_z(-9.81);
        ASSERT_OK(s.SetGravity(g));
      }
      if (i == 20) {
        Pressure pr;
        pr.set_pascals(3e3);
        pr.mutable_region()->mutable_box()->mutable_min()->set_z(2.99);
        pr.mutable_region()->mutable_box()->mutable_max()->set_x(3);
        pr.mutable_region()->mutable_box()->mutable_max()->set_y(3);
        pr.mutable_region()->mutable_box()->mutable_max()->set_z(3.01);
        ASSERT_OK(s.AddPressure(pr));
      }
      ASSERT_OK(s.Step());
      const StepStats& st = s.last_step();
      Trajectory& t = k == 0 ? a : b;
      t.p.push_back(s.control_positions());
      if (k == 0) {
        // The first step also finds the forces at the start (frames, energy).
        EXPECT_EQ(st.element_passes, (i == 0 ? 2 : 1) + st.cg_iterations + st.warm_start_rechecks)
            << "folded, step " << i;
        EXPECT_EQ(st.frame_passes, 1) << "folded, step " << i;
      } else {
        // The reference path: F (recomputed after an edit), then one Kt
        // product for F - h Kt (v + dv0).
        const bool edited = i % 3 == 0 || i == 10 || i == 20;
        EXPECT_EQ(st.element_passes, (edited ? 3 : 2) + st.cg_iterations + st.warm_start_rechecks)
            << "two-pass, step " << i;
      }
    }
  }
  const double dev = Deviation(a, b, rest);
  std::printf("with load edits: positions deviate %.2e of the displacement\n", dev);
  EXPECT_LT(dev, 1e-9);
}

TEST(SolidImplicitTest, FoldedRhsGivesTheSameBitsForAnyThreadCount) {
  const std::string text = BlockScene(1e-4);
  std::vector<std::string> states;
  for (const char* threads : {"1", "2", "3"}) {
    auto s = testing::WithThreadsEnv(threads, [&] { return Make(text); });
    ASSERT_NE(s, nullptr);
    Advance(*s, 25);
    states.push_back(s->SaveState());
  }
  EXPECT_EQ(states[0], states[1]) << "1 and 2 threads";
  EXPECT_EQ(states[0], states[2]) << "1 and 3 threads";
}

}  // namespace
}  // namespace dynsolid::solid
