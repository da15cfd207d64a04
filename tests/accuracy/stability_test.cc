// Stiff and extreme cases (small sizes; the cases and the energy
// account are solver/tools/stability_cases.h, which the stability report runs at
// more steps): backward Euler stays bounded (no energy growth beyond
// round-off); central difference either runs (sub-stepping) or refuses /
// rolls back and says why; no NaN ever reaches the state or the outputs.
#include <cctype>
#include <cmath>
#include <ostream>
#include <string>

#include <gtest/gtest.h>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/tools/stability_cases.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::stability {
namespace {

using ::testing::HasSubstr;

// Each case at a small step (300 steps) and at 1/30 s (the cases'
// duration, at most 1 s, except the inverting load's 3 s).
struct Param {
  Case c;
  bool large_step;
};

void PrintTo(const Param& p, std::ostream* os) {
  *os << p.c.name << (p.large_step ? " at h = 1/30 s" : " at h = 1e-3 s");
}

std::vector<Param> Params() {
  std::vector<Param> out;
  for (const Case& c : Cases()) {
    out.push_back({c, false});
    out.push_back({c, true});
  }
  return out;
}

RunOptions OptionsFor(Param& p) {
  RunOptions o;
  if (p.large_step) {
    p.c.h = 1.0 / 30;
    o.steps = static_cast<int>(std::ceil(p.c.duration * 30 - 1e-9));
  } else {
    p.c.h = 1e-3;
    o.steps = 300;
  }
  o.max_substeps = 2000;
  return o;
}

class StabilityTest : public ::testing::TestWithParam<Param> {};

std::string Describe(const Outcome& o) {
  return absl::StrFormat(
      "energy ratio %.6f (central velocity %.6f, final %.6f, late growth %.6f), %d/%d steps, %lld rollbacks, "
      "sub-steps %d -> %d, min volume ratio %.3g, status: %s",
      o.energy_ratio, o.central_energy_ratio, o.final_energy_ratio, o.late_growth_ratio, o.steps_done, o.steps,
      static_cast<long long>(o.rollbacks), o.substeps_start, o.substeps_end, o.min_volume_ratio,
      o.create.ok() ? o.final_status.ToString() : o.create.ToString());
}

TEST_P(StabilityTest, BackwardEulerStaysBounded) {
  Param p = GetParam();
  const RunOptions options = OptionsFor(p);
  const Outcome o = RunCase(p.c, Integrator::kBackwardEuler, options);
  std::printf("%s h=%.4g backward Euler: %s\n", p.c.name.c_str(), p.c.h, Describe(o).c_str());
  ASSERT_OK(o.create);
  EXPECT_TRUE(o.always_finite) << "NaN or inf reached the state";
  EXPECT_OK(o.final_status);
  EXPECT_EQ(o.steps_done, o.steps);
  EXPECT_EQ(o.rollbacks, 0);
  if (p.c.name == "spin_10_rad_s" && p.large_step) {
    // Known limitation (reported): the linearized step holds the element
    // frames fixed over the step, and a 0.33 rad turn per step reads part of
    // the rotation as strain; the first step gains energy (~29 %), which the
    // scheme then dissipates. Bounded, and falling after the first half.
    EXPECT_LT(o.energy_ratio, 1.5) << Describe(o);
    EXPECT_LT(o.late_growth_ratio, 1.0) << Describe(o);
    EXPECT_LT(o.final_energy_ratio, o.energy_ratio) << Describe(o);
  } else {
    // Tighter than the report's verdict tolerance: backward Euler's H never
    // rises above H(0) here except by ~2e-6 on the spin at 1 ms.
    EXPECT_LE(o.energy_ratio, 1 + 1e-5) << "energy grew: " << Describe(o);
  }
}

TEST_P(StabilityTest, CentralDifferenceRunsOrSaysWhy) {
  Param p = GetParam();
  const RunOptions options = OptionsFor(p);
  const Outcome o = RunCase(p.c, Integrator::kCentralDifference, options);
  std::printf("%s h=%.4g central difference: %s\n", p.c.name.c_str(), p.c.h, Describe(o).c_str());
  EXPECT_TRUE(o.always_finite) << "NaN or inf reached the state";
  if (!o.create.ok()) {
    // Too stiff for explicit steps at this h: a clear refusal, not a blow-up.
    EXPECT_THAT(o.create, testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                            HasSubstr("explicit sub-steps")));
    return;
  }
  if (!o.final_status.ok()) {
    // The guard gave up: it says so, after rolling back, from the last good state.
    EXPECT_THAT(o.final_status, testing::StatusIs(absl::StatusCode::kFailedPrecondition,
                                                  HasSubstr("state restored")));
    EXPECT_GT(o.rollbacks, 0);
    return;
  }
  EXPECT_EQ(o.steps_done, o.steps);
  // No sustained growth (central difference's chord-velocity energy
  // oscillates; an instability grows from one half of the run to the next).
  EXPECT_LE(o.late_growth_ratio, 1 + kGrowthTolerance) << Describe(o);
  // Rollbacks, when there were any, left more sub-steps.
  if (o.rollbacks > 0) {
    EXPECT_GT(o.substeps_end, o.substeps_start);
  }
}

INSTANTIATE_TEST_SUITE_P(Cases, StabilityTest, ::testing::ValuesIn(Params()),
                         [](const ::testing::TestParamInfo<Param>& info) {
                           std::string name = info.param.c.name + (info.param.large_step ? "_h30" : "_h1e3");
                           for (char& ch : name) {
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           }
                           return name;
                         });

// The first of Cases() named `name`; NotFound when there is none.
absl::StatusOr<Case> CaseNamed(const std::string& name) {
  for (const Case& c : Cases()) {
    if (c.name == name) return c;
  }
  return absl::NotFoundError(absl::StrCat("no ", name, " case"));
}

// The inverting load does invert cells (a level-1 cell's signed volume
// changes sign), and both schemes come through with finite states.
TEST(StabilityCasesTest, InvertingLoadInvertsCells) {
  ASSERT_OK_AND_ASSIGN(Case c, CaseNamed("inverting_load"));
  c.h = 1.0 / 30;
  RunOptions o;
  o.steps = 90;
  for (Integrator integrator : {Integrator::kBackwardEuler, Integrator::kCentralDifference}) {
    const Outcome out = RunCase(c, integrator, o);
    EXPECT_TRUE(out.always_finite) << Name(integrator);
    EXPECT_LT(out.min_volume_ratio, 0) << Name(integrator) << ": no cell inverted";
  }
}

// Penalty springs of 1e9 N/m need about 2000 explicit sub-steps per 1/30 s
// step: with a cap of 100 Create refuses, naming the field, the count and
// the stable step; backward Euler takes the same scene.
TEST(StabilityCasesTest, ExplicitStepsAboveTheCapAreRefusedWithTheReason) {
  ASSERT_OK_AND_ASSIGN(Case c, CaseNamed("penalty_1e9"));
  c.h = 1.0 / 30;
  RunOptions o;
  o.steps = 3;
  o.max_substeps = 100;
  const Outcome cd = RunCase(c, Integrator::kCentralDifference, o);
  EXPECT_THAT(cd.create,
              testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                ::testing::AllOf(HasSubstr("solver.time_step"),
                                                 HasSubstr("explicit sub-steps (stable step"),
                                                 HasSubstr("max_substeps is 100"))));
  EXPECT_EQ(cd.steps_done, 0);
  const Outcome be = RunCase(c, Integrator::kBackwardEuler, o);
  EXPECT_OK(be.create);
  EXPECT_TRUE(be.completed());
  EXPECT_LE(be.energy_ratio, 1 + kEnergyTolerance);
}

// The 180-degree twist: released with strain energy, no loads; backward
// Euler only loses it; the central-difference run (sub-stepped) stays
// finite and its energy does not keep growing.
TEST(StabilityCasesTest, TwistReleasedFromHalfATurn) {
  ASSERT_OK_AND_ASSIGN(Case c, CaseNamed("twist_180"));
  c.h = 1e-2;
  RunOptions o;
  o.steps = 50;
  const Outcome be = RunCase(c, Integrator::kBackwardEuler, o);
  ASSERT_OK(be.create);
  EXPECT_GT(be.initial_energy, 0) << "the twisted state holds strain energy";
  EXPECT_DOUBLE_EQ(be.peak_mechanical, be.initial_energy);
  EXPECT_LE(be.energy_ratio, 1 + kEnergyTolerance);
  EXPECT_LT(be.final_energy_ratio, 0.5) << "backward Euler damps the released twist";
  const Outcome cd = RunCase(c, Integrator::kCentralDifference, o);
  ASSERT_OK(cd.create);
  EXPECT_TRUE(cd.always_finite);
  EXPECT_OK(cd.final_status);
  EXPECT_LE(cd.late_growth_ratio, 1 + kGrowthTolerance) << Describe(cd);
}

// Twisted() is a rotation of each cross section: distances to the axis
// are kept, and the end x = length turns by the full angle.
TEST(StabilityCasesTest, TwistedTurnsEachSection) {
  Points rest(3, 3);
  rest << 0, 0.25, 0.25, 1, 0.25, -0.25, 2, -0.25, 0.25;
  const Points p = Twisted(rest, M_PI, 2.0, 0, 0);
  EXPECT_NEAR(p(0, 1), 0.25, 1e-15);
  EXPECT_NEAR(p(0, 2), 0.25, 1e-15);
  // x = 1: a quarter turn of (0.25, -0.25) gives (0.25, 0.25).
  EXPECT_NEAR(p(1, 1), 0.25, 1e-15);
  EXPECT_NEAR(p(1, 2), 0.25, 1e-15);
  // x = 2: half a turn.
  EXPECT_NEAR(p(2, 1), 0.25, 1e-15);
  EXPECT_NEAR(p(2, 2), -0.25, 1e-15);
}

// Near-degenerate cells: a control cell 1e-3 m thick is accepted; as an
// element (0 levels) it governs the stable step (about sqrt(1e-3 / 1) of
// the neighbours' scale), which subdivision (1 level) smooths away; both
// run bounded with backward Euler and with explicit sub-steps.
TEST(StabilityCasesTest, ThinLayerGovernsTheStableStepAtLevelZero) {
  Outcome l0, l1;
  for (const Case& base : Cases()) {
    if (base.name.rfind("thin_layer_L", 0) != 0) continue;
    Case c = base;
    c.h = 1e-3;
    RunOptions o;
    o.steps = 50;
    const Outcome cd = RunCase(c, Integrator::kCentralDifference, o);
    ASSERT_OK(cd.create) << c.name;
    EXPECT_OK(cd.final_status) << c.name;
    (c.levels == 0 ? l0 : l1) = cd;
  }
  ASSERT_GT(l0.stable_step, 0);
  ASSERT_GT(l1.stable_step, 0);
  std::printf("stable step: thin cell as an element %.4g s, subdivided %.4g s\n", l0.stable_step,
              l1.stable_step);
  EXPECT_LT(l0.stable_step, 0.2 * l1.stable_step);
  EXPECT_GT(l0.substeps_start, 1) << "1 ms is above the thin element's stable step";
}

}  // namespace
}  // namespace dynsolid::stability
