// The corotational model with one frame per control cell
// (solver.corotation: CONTROL_CELL, models/cell_corotation.h) against the
// element model it is summed from: the same forces for small displacements
// (the same linear stiffness A^T K A), no force for rigid motion, forces
// that turn with the solid and sum to zero, the same trajectory as the
// element model while rotations stay small, the same bits for any thread
// count, and the scene rules that name the field.
#include <cmath>
#include <memory>
#include <random>
#include <string>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

using ::testing::HasSubstr;

// A torus of curved, distinct cells (no two share a stiffness) with a
// stiffer painted region, or a block (congruent cells share one).
std::string SceneText(const std::string& mesh, const std::string& corotation,
                      const std::string& extra = "") {
  return absl::StrCat("name: \"cells\"\n", mesh, R"pb(
    subdivision { levels: 1 }
    materials {
      base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 20 }
      regions {
        region { box { min { x: 0.3 y: -2 z: -2 } max { x: 2 y: 2 z: 2 } } }
        material { young_modulus: 6e5 poisson_ratio: 0.35 density: 1500 damping: 20 }
      }
    }
    )pb", extra, "solver { model: COROTATIONAL corotation: ", corotation, " time_step: 1e-3 }\n");
}

const char kTorus[] = "mesh { torus { major_radius: 1 tube_half_width: 0.3 segments: 8 cross: 2 } }";
const char kBlock[] = "mesh { block { nx: 3 ny: 3 nz: 4 } }";

std::unique_ptr<Solid> Make(const std::string& text, int threads = 2) {
  return testing::MakeSolid(text, threads);
}

Points Perturbed(const Points& rest, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Points p = rest;
  for (int64_t i = 0; i < p.rows(); ++i)
    for (int c = 0; c < 3; ++c) p(i, c) += amplitude * u(rng);
  return p;
}

Eigen::Matrix3d Turn(double angle, Eigen::Vector3d axis) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

TEST(CellCorotationTest, SmallDisplacementsGiveTheElementModelsForces) {
  for (const char* mesh : {kTorus, kBlock}) {
    SCOPED_TRACE(mesh);
    std::unique_ptr<Solid> cells = Make(SceneText(mesh, "CONTROL_CELL"));
    std::unique_ptr<Solid> elements = Make(SceneText(mesh, "ELEMENT"));
    ASSERT_NE(cells, nullptr);
    ASSERT_NE(elements, nullptr);
    EXPECT_GT(cells->build_report().corotated_cells, 0);
    EXPECT_EQ(elements->build_report().corotated_cells, 0);
    // The same linear stiffness, so the same stable step (estimated with
    // products in control space: to rounding).
    EXPECT_NEAR(cells->build_report().omega_max, elements->build_report().omega_max,
                1e-9 * elements->build_report().omega_max);
    const Points rest = cells->control_positions();
    for (double amplitude : {1e-7, 1e-5}) {
      const Points p = Perturbed(rest, amplitude, 7);
      const Points fc = cells->InternalControlForces(p);
      const Points fe = elements->InternalControlForces(p);
      // Both are K u + O(u^2): they differ by the rotations' second order.
      EXPECT_LE((fc - fe).norm(), 50 * amplitude * fe.norm()) << amplitude;
      EXPECT_NEAR(cells->StrainEnergy(p), elements->StrainEnergy(p),
                  100 * amplitude * elements->StrainEnergy(p));
    }
  }
}

TEST(CellCorotationTest, RigidMotionIsFreeAndForcesTurnWithTheSolid) {
  std::unique_ptr<Solid> s = Make(SceneText(kTorus, "CONTROL_CELL"));
  ASSERT_NE(s, nullptr);
  const Points rest = s->control_positions();
  const Points p = Perturbed(rest, 0.03, 11);  // 10 % of a cell: a real deformation
  const Points f = s->InternalControlForces(p);
  const double e = s->StrainEnergy(p);
  ASSERT_GT(e, 0);
  ASSERT_GT(f.norm(), 0);
  // Linear momentum: the internal forces sum to zero.
  EXPECT_LE(f.colwise().sum().norm(), 1e-9 * f.norm());
  for (double angle : {0.4, 2.0, 3.1}) {
    SCOPED_TRACE(angle);
    const Eigen::Matrix3d q = Turn(angle, Eigen::Vector3d(1, -2, 0.5));
    const Eigen::RowVector3d t(3, -1, 7);
    // Rest turned and moved: no force, no energy.
    Points moved = (rest * q.transpose()).rowwise() + t;
    EXPECT_LE(s->InternalControlForces(moved).norm(), 1e-9 * f.norm());
    EXPECT_LE(s->StrainEnergy(moved), 1e-12 * e);
    // The deformed state turned and moved: the same energy, forces turned.
    moved = (p * q.transpose()).rowwise() + t;
    EXPECT_NEAR(s->StrainEnergy(moved), e, 1e-9 * e);
    EXPECT_LE((s->InternalControlForces(moved) - f * q.transpose()).norm(), 1e-9 * f.norm());
  }
}

TEST(CellCorotationTest, FollowsTheElementModelWhileRotationsStaySmall) {
  // The block, fixed at its base, under a sideways pull at its top: it bends
  // a few degrees and sways.
  const std::string extra = R"pb(
    constraints { fixed { box { min { x: -0.01 y: -0.01 z: -0.01 } max { x: 3.01 y: 3.01 z: 0.01 } } } }
    loads { point_forces { position { x: 1.5 y: 1.5 z: 3.9 } force { x: 2e4 y: 5e3 z: 0 } } }
  )pb";
  std::unique_ptr<Solid> cells = Make(SceneText(kBlock, "CONTROL_CELL", extra));
  std::unique_ptr<Solid> elements = Make(SceneText(kBlock, "ELEMENT", extra));
  ASSERT_NE(cells, nullptr);
  ASSERT_NE(elements, nullptr);
  const Points rest = cells->control_positions();
  double largest = 0, apart = 0;
  for (int i = 0; i < 300; ++i) {
    ASSERT_OK(cells->Step());
    ASSERT_OK(elements->Step());
    const Points& a = cells->control_positions();
    const Points& b = elements->control_positions();
    largest = std::max(largest, (b - rest).rowwise().norm().maxCoeff());
    apart = std::max(apart, (a - b).rowwise().norm().maxCoeff());
  }
  std::printf("largest displacement %.4g m, trajectories apart by at most %.3g m\n", largest, apart);
  ASSERT_GT(largest, 0.05);  // it moved
  EXPECT_LE(apart, 0.02 * largest);
}

TEST(CellCorotationTest, SameBitsForAnyThreadCount) {
  const std::string text = SceneText(kTorus, "CONTROL_CELL", R"pb(
    initial { angular_velocity { x: 0.3 z: 2 } }
    loads { gravity { z: -9.81 } }
  )pb");
  std::unique_ptr<Solid> one = Make(text, 1);
  std::unique_ptr<Solid> two = Make(text, 2);
  std::unique_ptr<Solid> three = Make(text, 3);
  ASSERT_NE(one, nullptr);
  for (int i = 0; i < 40; ++i) {
    ASSERT_OK(one->Step());
    ASSERT_OK(two->Step());
    ASSERT_OK(three->Step());
  }
  EXPECT_EQ(one->SaveState(), two->SaveState());
  EXPECT_EQ(one->SaveState(), three->SaveState());
}

TEST(CellCorotationTest, ASpinningFreeSolidKeepsItsEnergy) {
  // Undamped, free, spinning at 2 rad/s: the frames turn through a whole
  // revolution; the energy stays (central difference keeps it to O(h^2)).
  std::string text = SceneText(kTorus, "CONTROL_CELL", "initial { angular_velocity { z: 2 } }\n");
  for (size_t at; (at = text.find("damping: 20")) != std::string::npos;) text.replace(at, 11, "damping: 0");
  std::unique_ptr<Solid> s = Make(text);
  ASSERT_NE(s, nullptr);
  const Energies start = s->ComputeEnergies();
  double low = 1e300, high = 0, strain = 0;
  for (int i = 0; i < 3200; ++i) {
    ASSERT_OK(s->Step());
    const Energies e = s->ComputeEnergies();
    low = std::min(low, e.kinetic + e.strain);
    high = std::max(high, e.kinetic + e.strain);
    strain = std::max(strain, e.strain);
  }
  EXPECT_EQ(s->rollbacks(), 0);
  // Only the centrifugal stretch strains it (rho w^2 R^2 / E = 4 %), not
  // the turning.
  EXPECT_LT(strain, 0.1 * start.kinetic);
  EXPECT_GT(low, 0.98 * start.kinetic);
  EXPECT_LT(high, 1.02 * start.kinetic);
}

TEST(CellCorotationTest, BackwardEulerFollowsTheElementModel) {
  // Backward Euler holds each step's frames (cell_corotation.h): the same
  // sway as the element model's backward Euler, and, with the folded
  // right-hand side, the same as the two-pass reference to CG's tolerance.
  const std::string extra = R"pb(
    constraints { fixed { box { min { x: -0.01 y: -0.01 z: -0.01 } max { x: 3.01 y: 3.01 z: 0.01 } } } }
    loads { point_forces { position { x: 1.5 y: 1.5 z: 3.9 } force { x: 2e4 y: 5e3 z: 0 } } }
  )pb";
  auto implicit = [&](const std::string& corotation) {
    std::string text = SceneText(kBlock, corotation, extra);
    text.replace(text.find("time_step: 1e-3"), 15,
                 "time_step: 4e-3 integrator: BACKWARD_EULER cg_tolerance: 1e-8");
    return Make(text);
  };
  std::unique_ptr<Solid> cells = implicit("CONTROL_CELL");
  std::unique_ptr<Solid> elements = implicit("ELEMENT");
  ASSERT_NE(cells, nullptr);
  ASSERT_NE(elements, nullptr);
  ASSERT_TRUE(cells->build_report().implicit);
  std::unique_ptr<Solid> two_pass = implicit("CONTROL_CELL");
  two_pass->SetImplicitTwoPassForTesting(true);
  const Points rest = cells->control_positions();
  double largest = 0, apart = 0, folded_apart = 0;
  for (int i = 0; i < 100; ++i) {
    ASSERT_OK(cells->Step());
    ASSERT_OK(elements->Step());
    ASSERT_OK(two_pass->Step());
    ASSERT_EQ(cells->last_step().rollbacks, 0);
    const Points& a = cells->control_positions();
    const Points& b = elements->control_positions();
    largest = std::max(largest, (b - rest).rowwise().norm().maxCoeff());
    apart = std::max(apart, (a - b).rowwise().norm().maxCoeff());
    folded_apart = std::max(folded_apart, (a - two_pass->control_positions()).rowwise().norm().maxCoeff());
  }
  std::printf("largest displacement %.4g m, apart from the element model by %.3g m, folded from "
              "two-pass by %.3g m\n", largest, apart, folded_apart);
  ASSERT_GT(largest, 0.05);
  EXPECT_LE(apart, 0.02 * largest);
  EXPECT_LE(folded_apart, 1e-5 * largest);
  // The strain energy each step carries: the two-pass step's is the
  // model's at the new state; the folded step's is in the frames of the
  // step's start (no pass of its own), second order away.
  const double exact = two_pass->StrainEnergy(two_pass->control_positions());
  EXPECT_NEAR(two_pass->ComputeEnergies().strain, exact, 1e-9 * exact);
  EXPECT_NEAR(cells->ComputeEnergies().strain, cells->StrainEnergy(cells->control_positions()),
              1e-3 * exact);
}

TEST(CellCorotationTest, SceneRulesNameTheField) {
  auto local = scene::ParseScene(
      absl::StrCat("name: \"x\" ", kBlock, " solver { model: LOCAL_FRAME corotation: CONTROL_CELL }"),
      "test");
  ASSERT_FALSE(local.ok());
  EXPECT_THAT(std::string(local.status().message()), HasSubstr("solver.corotation"));
  EXPECT_THAT(std::string(local.status().message()), HasSubstr("COROTATIONAL"));
  auto by_default = scene::ParseScene(
      absl::StrCat("name: \"x\" ", kBlock, " solver { corotation: CONTROL_CELL }"), "test");
  ASSERT_FALSE(by_default.ok());  // the default model is the local-frame one
}

}  // namespace
}  // namespace dynsolid::solid
