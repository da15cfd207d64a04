// Stiff and extreme cases (issue 4, small sizes): backward Euler stays
// bounded; the explicit scheme either runs (sub-stepping, guard rollbacks)
// or says why it cannot; no NaN ever reaches the state.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

struct Case {
  std::string name;
  std::string material;  // Materials body
  std::string extra;     // loads / constraints / initial
  double h;
};

std::string SceneText(const Case& c, const char* integrator) {
  return absl::StrFormat(R"pb(
    name: "%s"
    mesh { block { nx: 2 ny: 1 nz: 1 } }
    subdivision { levels: 1 }
    materials { %s }
    %s
    solver { model: COROTATIONAL integrator: %s time_step: %.17g max_substeps: 2000 }
  )pb", c.name, c.material, c.extra, integrator, c.h);
}

const char* kFixedEnd =
    "constraints { fixed { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } } } }";

std::vector<Case> Cases() {
  return {
      {"soft_1e3", "base { young_modulus: 1e3 }", std::string(kFixedEnd) +
           " loads { gravity { z: -9.81 } }", 1.0 / 30},
      {"stiff_1e10", "base { young_modulus: 1e10 }", std::string(kFixedEnd) +
           " loads { point_forces { position { x: 1.9 y: 0.5 z: 0.5 } force { z: -1e6 } } }",
       1.0 / 30},
      {"nearly_incompressible", "base { young_modulus: 1e6 poisson_ratio: 0.499 }",
       std::string(kFixedEnd) + " loads { gravity { z: -9.81 } }", 1e-3},
      {"penalty_1e9", "base { young_modulus: 1e5 }",
       "constraints { springs { region { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } } } "
       "stiffness: 1e9 } } loads { gravity { z: -9.81 } }",
       1e-3},
      {"inverting_load", "base { young_modulus: 1e3 }",
       std::string(kFixedEnd) +
           " loads { point_forces { position { x: 1.9 y: 0.5 z: 0.5 } force { x: -1e5 } } }",
       1e-3},
      {"spin_10_rad_s", "base { young_modulus: 1e6 }",
       "initial { angular_velocity { z: 10 } }", 1e-3},
      {"density_ratio_1e6",
       "base { young_modulus: 1e6 density: 1 } regions { region { box { min { x: 1 y: -1 z: -1 } "
       "max { x: 3 y: 2 z: 2 } } } material { young_modulus: 1e6 density: 1e6 } }",
       std::string(kFixedEnd) + " loads { gravity { z: -9.81 } }", 1e-3},
  };
}

class StabilityTest : public ::testing::TestWithParam<Case> {};

std::unique_ptr<Solid> Make(const std::string& text, absl::Status* status) {
  auto scene = scene::ParseScene(text, "case");
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, "", std::nullopt);
  EXPECT_OK(d);
  auto s = Solid::Create(*scene, *std::move(d));
  *status = s.status();
  return s.ok() ? *std::move(s) : nullptr;
}

TEST_P(StabilityTest, BackwardEulerStaysBounded) {
  const Case& c = GetParam();
  absl::Status status;
  auto s = Make(SceneText(c, "BACKWARD_EULER"), &status);
  ASSERT_OK(status);
  const int steps = static_cast<int>(std::min(200.0, std::ceil(1.0 / c.h)));
  double peak = 0;
  for (int i = 0; i < steps; ++i) {
    const absl::Status st = s->Step();
    ASSERT_OK(st) << c.name << " step " << i;
    ASSERT_TRUE(s->control_positions().allFinite()) << c.name;
    const Energies e = s->ComputeEnergies();
    ASSERT_TRUE(std::isfinite(e.kinetic) && std::isfinite(e.strain)) << c.name;
    peak = std::max(peak, e.kinetic + e.strain);
  }
  std::printf("%-24s backward Euler: %d steps of %.4g s, peak energy %.4g J, %lld rollbacks\n",
              c.name.c_str(), steps, c.h, peak, static_cast<long long>(s->rollbacks()));
}

TEST_P(StabilityTest, CentralDifferenceRunsOrSaysWhy) {
  const Case& c = GetParam();
  absl::Status status;
  auto s = Make(SceneText(c, "CENTRAL_DIFFERENCE"), &status);
  if (!status.ok()) {
    // Too stiff for explicit steps at this h: a clear refusal, not a blow-up.
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
    EXPECT_NE(std::string(status.message()).find("sub-steps"), std::string::npos) << status;
    std::printf("%-24s central difference: refused (%s)\n", c.name.c_str(),
                std::string(status.message()).c_str());
    return;
  }
  const int steps = static_cast<int>(std::min(100.0, std::ceil(0.2 / c.h)));
  for (int i = 0; i < steps; ++i) {
    const absl::Status st = s->Step();
    ASSERT_TRUE(s->control_positions().allFinite()) << c.name << ": NaN reached the state";
    if (!st.ok()) {
      // The guard gave up: it says so and the state is the last good one.
      EXPECT_EQ(st.code(), absl::StatusCode::kFailedPrecondition) << st;
      std::printf("%-24s central difference: stopped at step %d (%s)\n", c.name.c_str(), i,
                  std::string(st.message()).c_str());
      return;
    }
  }
  std::printf("%-24s central difference: %d steps, %d sub-steps, %lld rollbacks\n", c.name.c_str(),
              steps, s->build_report().substeps, static_cast<long long>(s->rollbacks()));
}

INSTANTIATE_TEST_SUITE_P(Cases, StabilityTest, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<Case>& info) { return info.param.name; });

}  // namespace
}  // namespace dynsolid::solid
