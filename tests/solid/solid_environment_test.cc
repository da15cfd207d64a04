// The environment (scene.proto Environment, contact/obstacle_contact.h): a
// block dropped onto the floor never sinks into it by more than 1 % of its
// size and comes to rest on it; a block thrown at 10 m/s at a thin wall or a
// ball does not pass through; friction holds a block on a 20-degree slope
// when the coefficient is above tan(20) and lets it slide (at the rate
// Coulomb's law gives) when it is below; the same bits for any thread
// count; a saved state in contact continues bit for bit; bad environments
// are refused naming the field.
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

// A 1 m cube of 2 x 2 x 2 cells at one level, its lowest corner at `origin`.
std::string Block(const std::string& origin, const std::string& rest,
                  const std::string& model = "corotation: CONTROL_CELL",
                  const std::string& damping = "1000") {
  return absl::StrCat(R"pb(
    name: "env"
    mesh { block { nx: 2 ny: 2 nz: 2 size { x: 1 y: 1 z: 1 } origin { )pb",
                      origin, R"pb( } } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 5e6 poisson_ratio: 0.3 density: 1000 damping: )pb",
                      damping, R"pb( } }
    solver { model: COROTATIONAL )pb",
                      model, " time_step: 1e-3 }\n", rest);
}

double MinZ(const Solid& s) { return s.SurfacePositions().col(2).minCoeff(); }
double MaxX(const Solid& s) { return s.SurfacePositions().col(0).maxCoeff(); }
Eigen::Vector3d Centroid(const Solid& s) {
  return s.SurfacePositions().colwise().mean().transpose();
}

TEST(EnvironmentTest, ABlockDroppedFromTwoMetresStaysAboveTheFloorAndComesToRest) {
  for (const char* model : {"corotation: CONTROL_CELL", "corotation: ELEMENT",
                            "corotation: CONTROL_CELL integrator: BACKWARD_EULER"}) {
    SCOPED_TRACE(model);
    std::unique_ptr<Solid> s = testing::MakeSolid(
        Block("x: 0 y: 0 z: 2",
              "loads { gravity { z: -9.81 } }\n"
              "environment { floor { normal { z: 1 } } friction: 0.5 stiffness: 20 }\n",
              model, "2000"),
        2);
    ASSERT_NE(s, nullptr);
    EXPECT_GT(s->build_report().contact_kappa, 0);
    double lowest = INFINITY, peak_kinetic = 0, last_kinetic = 0;
    for (int step = 0; step < 4000; ++step) {
      ASSERT_OK(s->Step());
      lowest = std::min(lowest, MinZ(*s));
      last_kinetic = s->ComputeEnergies().kinetic;
      peak_kinetic = std::max(peak_kinetic, last_kinetic);
    }
    // It fell (about 2 m; the mass-proportional damping of 2/s slows it
    // as a thick air would: 3.9 m/s after 2 m) and hit the floor.
    EXPECT_GT(peak_kinetic, 0.5 * 1000 * 3.5 * 3.5);
    // Never below the floor by more than 1 % of its size (1 m).
    EXPECT_GT(lowest, -0.01) << "sank " << -lowest << " m into the floor";
    // At rest on it, about 3.2 s after the impact.
    EXPECT_LT(last_kinetic, 1e-3 * peak_kinetic);
    EXPECT_NEAR(MinZ(*s), 0.0, 0.01);
  }
}

TEST(EnvironmentTest, ABlockThrownAtTenMetresPerSecondDoesNotPassThroughAWall) {
  // A 4 cm wall 0.5 m in front of the block, and no gravity.
  std::unique_ptr<Solid> s = testing::MakeSolid(
      Block("x: 0 y: 0 z: 0",
            "initial { linear_velocity { x: 10 } }\n"
            "environment { obstacles { box { min { x: 1.5 y: -2 z: -2 } "
            "max { x: 1.54 y: 3 z: 3 } } } }\n"),
      2);
  ASSERT_NE(s, nullptr);
  double furthest = -INFINITY;
  for (int step = 0; step < 300; ++step) {
    ASSERT_OK(s->Step());
    furthest = std::max(furthest, MaxX(*s));
  }
  EXPECT_GT(furthest, 1.5 - 1e-3);  // it reached the wall
  EXPECT_LT(furthest, 1.54) << "a vertex passed the wall";
  // And it bounced back.
  EXPECT_LT(MaxX(*s), 1.5);
  const Eigen::Vector3d c0 = Centroid(*s);
  ASSERT_OK(s->Step());
  EXPECT_LT(Centroid(*s).x(), c0.x());
}

TEST(EnvironmentTest, ABlockThrownAtABallBouncesOffIt) {
  std::unique_ptr<Solid> s = testing::MakeSolid(
      Block("x: 0 y: 0 z: 0",
            "initial { linear_velocity { x: 10 } }\n"
            "environment { stiffness: 20 "
            "obstacles { sphere { center { x: 1.8 y: 0.5 z: 0.5 } radius: 0.3 } } }\n"),
      2);
  ASSERT_NE(s, nullptr);
  for (int step = 0; step < 300; ++step) {
    ASSERT_OK(s->Step());
    const Points x = s->SurfacePositions();
    for (int64_t i = 0; i < x.rows(); ++i) {
      const double r = (x.row(i).transpose() - Eigen::Vector3d(1.8, 0.5, 0.5)).norm();
      // (A 10 m/s impact on a curved 30 cm ball sinks further than the
      // floor's estimate, 2.4 v L / (stiffness c) = 1.7 cm: a third of the
      // radius at most.)
      ASSERT_GT(r, 0.2) << "vertex " << i << " is " << 0.3 - r << " m inside the ball";
    }
  }
  const Eigen::Vector3d c0 = Centroid(*s);
  ASSERT_OK(s->Step());
  EXPECT_LT(Centroid(*s).x(), c0.x());  // bounced back
}

// The block on a 20-degree slope: the floor is level and gravity tilted by
// 20 degrees (the same thing), sliding towards +x. Its damping density
// (20 000 kg/m^3/s: a drag of 20/s on every velocity) settles it within
// 0.3 s and makes the slide analytic: dv/dt = a - 20 v.
constexpr double kSlopeDrag = 20;
double SlideOnSlope(double friction, double seconds) {
  const double a = 20 * kPi / 180, g = 9.81;
  std::unique_ptr<Solid> s = testing::MakeSolid(
      Block("x: 0 y: 0 z: 0",
            absl::StrCat("loads { gravity { x: ", g * std::sin(a), " z: ", -g * std::cos(a),
                         " } }\n environment { floor { normal { z: 1 } } friction: ", friction,
                         " }\n"),
            "corotation: CONTROL_CELL", absl::StrCat(1000 * kSlopeDrag)),
      2);
  if (s == nullptr) return NAN;
  for (int step = 0; step < 300; ++step) {
    if (!s->Step().ok()) return NAN;
  }
  const double x0 = Centroid(*s).x();
  const int steps = static_cast<int>(std::lround(seconds / s->time_step()));
  for (int step = 0; step < steps; ++step) {
    if (!s->Step().ok()) return NAN;
  }
  return Centroid(*s).x() - x0;
}

TEST(EnvironmentTest, FrictionHoldsABlockOnATwentyDegreeSlopeAboveTanTwentyAndNotBelow) {
  const double a = 20 * kPi / 180, g = 9.81, t = 1.0;
  ASSERT_LT(0.3, std::tan(a));
  ASSERT_GT(0.45, std::tan(a));
  const double held = SlideOnSlope(0.45, t);
  const double slid = SlideOnSlope(0.3, t);
  const double frictionless = SlideOnSlope(0.0, t);
  // Sliding, Coulomb's law and the drag: the terminal velocity
  // g (sin a - mu cos a) / drag, reached within 0.3 s (e^-6).
  auto predicted = [&](double mu) { return g * (std::sin(a) - mu * std::cos(a)) / kSlopeDrag * t; };
  EXPECT_LT(std::abs(held), 2e-3) << "held block moved " << held << " m";
  EXPECT_NEAR(slid / predicted(0.3), 1.0, 0.15) << slid << " m against " << predicted(0.3);
  EXPECT_NEAR(frictionless / predicted(0.0), 1.0, 0.15) << frictionless << " m against "
                                                         << predicted(0.0);
}

Points RunDropped(int threads, int steps) {
  std::unique_ptr<Solid> s = testing::MakeSolid(
      Block("x: 0 y: 0 z: 0.3",
            "loads { gravity { x: 2 z: -9.81 } }\n"
            "environment { floor { normal { z: 1 } } friction: 0.3 "
            "obstacles { box { min { x: 0.8 y: -1 z: -1 } max { x: 2 y: 2 z: 0.1 } } } }\n"),
      threads);
  if (s == nullptr) return Points();
  for (int k = 0; k < steps; ++k) {
    if (!s->Step().ok()) return Points();
  }
  return s->control_positions();
}

TEST(EnvironmentTest, TheSameBitsForAnyThreadCount) {
  const Points one = RunDropped(1, 400);
  const Points two = RunDropped(2, 400);
  const Points three = RunDropped(3, 400);
  ASSERT_GT(one.rows(), 0);
  EXPECT_TRUE(one == two);
  EXPECT_TRUE(one == three);
}

TEST(EnvironmentTest, ASavedStateInContactContinuesBitForBit) {
  const std::string text =
      Block("x: 0 y: 0 z: 0.1",
            "loads { gravity { x: 3 z: -9.81 } }\n"
            "environment { floor { normal { z: 1 } } friction: 0.4 }\n");
  std::unique_ptr<Solid> a = testing::MakeSolid(text, 2);
  ASSERT_NE(a, nullptr);
  for (int k = 0; k < 2000 && MinZ(*a) >= 0; ++k) ASSERT_OK(a->Step());
  ASSERT_LT(MinZ(*a), 0.0);  // in contact now
  const std::string saved = a->SaveState();
  std::unique_ptr<Solid> b = testing::MakeSolid(text, 1);
  ASSERT_NE(b, nullptr);
  ASSERT_OK(b->RestoreState(saved));
  for (int k = 0; k < 200; ++k) {
    ASSERT_OK(a->Step());
    ASSERT_OK(b->Step());
  }
  EXPECT_TRUE(a->control_positions() == b->control_positions());
  EXPECT_EQ(a->SaveState(), b->SaveState());
}

TEST(EnvironmentTest, PinsAndContactHoldTogether) {
  // The block's face x = 0 pinned, its bottom on the floor, gravity pulling
  // it down and sideways into a ball beside it.
  std::unique_ptr<Solid> s = testing::MakeSolid(
      Block("x: 0 y: 0 z: 0",
            "loads { gravity { x: 6 z: -9.81 } }\n"
            "constraints { fixed { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } } } }\n"
            "environment { floor { normal { z: 1 } } friction: 0.5 "
            "obstacles { sphere { center { x: 1.25 y: 0.5 z: 0.5 } radius: 0.2 } } }\n"),
      2);
  ASSERT_NE(s, nullptr);
  const Points rest = s->control_positions();
  std::vector<int64_t> pinned;
  for (int64_t i = 0; i < rest.rows(); ++i) {
    if (std::abs(rest(i, 0)) < 0.01) pinned.push_back(i);
  }
  ASSERT_FALSE(pinned.empty());
  for (int k = 0; k < 1500; ++k) {
    ASSERT_OK(s->Step());
    for (int64_t i : pinned) ASSERT_TRUE(s->control_positions().row(i) == rest.row(i));
  }
  EXPECT_EQ(s->rollbacks(), 0);
  EXPECT_GT(s->contact_stats().touching, 0);
  EXPECT_GT(MinZ(*s), -0.01);
  EXPECT_LT(MaxX(*s), 1.25);  // held off by the ball, not through it
}

TEST(EnvironmentTest, BadEnvironmentsAreRefusedNamingTheField) {
  const char* bad[][2] = {
      {"environment { floor { point { z: 0 } } }", "environment.floor.normal must not be zero"},
      {"environment { obstacles { box { min { x: 1 } max { x: 0 y: 1 z: 1 } } } }",
       "environment.obstacles[0].box must have min < max"},
      {"environment { obstacles { sphere { radius: -1 } } }",
       "environment.obstacles[0].sphere.radius must be > 0"},
      {"environment { obstacles { } }", "environment.obstacles[0] has no shape"},
      {"environment { friction: -0.1 }", "environment.friction must be >= 0"},
      {"environment { damping_ratio: 2 }", "environment.damping_ratio must be in [0, 1]"},
      {"environment { stiffness: -1 }", "environment.stiffness must be >= 0"},
  };
  for (const auto& [extra, message] : bad) {
    SCOPED_TRACE(extra);
    const absl::StatusOr<Scene> scene =
        scene::ParseScene(Block("x: 0 y: 0 z: 0", std::string(extra) + "\n"), "test");
    ASSERT_FALSE(scene.ok());
    EXPECT_THAT(std::string(scene.status().message()), HasSubstr(message));
  }
}

}  // namespace
}  // namespace dynsolid::solid
