// Loads within physics (solid/load_bounds.h): forces, pressures and gravity
// far beyond what a solid can take are refused with the bound, derived
// from the solid, in the message; loads too small to move anything in
// double precision are refused too; ordinary loads pass; a refused load
// changes nothing. The bounds scale with the solid: a stiffer solid takes
// proportionally more.
#include <cmath>
#include <memory>
#include <string>
#include <utility>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

using ::testing::HasSubstr;

// A 2 m cube of 2 x 2 x 2 cells, E as given, 1000 kg/m^3, its base pinned.
std::unique_ptr<Solid> Cube(double young, const std::string& loads = "") {
  return testing::MakeSolid(absl::StrCat(R"pb(
    name: "cube"
    mesh { block { nx: 2 ny: 2 nz: 2 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: )pb",
                                         young, R"pb( density: 1000 damping: 100 } }
    constraints { fixed { box { min { x: -1 y: -1 z: -0.01 } max { x: 3 y: 3 z: 0.01 } } } }
    solver { model: COROTATIONAL corotation: CONTROL_CELL time_step: 1e-3 }
  )pb",
                                         loads),
                            2);
}

PointForce Force(double fz) {
  PointForce f;
  f.mutable_position()->set_x(1);
  f.mutable_position()->set_y(1);
  f.mutable_position()->set_z(2);
  f.mutable_force()->set_z(fz);
  return f;
}

Pressure Press(double pa) {
  Pressure p;
  p.mutable_region()->mutable_box()->mutable_min()->set_z(1.99);
  p.mutable_region()->mutable_box()->mutable_min()->set_x(-1);
  p.mutable_region()->mutable_box()->mutable_min()->set_y(-1);
  p.mutable_region()->mutable_box()->mutable_max()->set_x(3);
  p.mutable_region()->mutable_box()->mutable_max()->set_y(3);
  p.mutable_region()->mutable_box()->mutable_max()->set_z(3);
  p.set_pascals(pa);
  return p;
}

Vec3 Gravity(double gz) {
  Vec3 g;
  g.set_z(gz);
  return g;
}

TEST(LoadBoundsTest, TheScaleIsTheSolids) {
  std::unique_ptr<Solid> s = Cube(1e6);
  ASSERT_NE(s, nullptr);
  const LoadScale scale = s->load_scale();
  EXPECT_NEAR(scale.size, 2 * std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(scale.young, 1e6, 1e-6);
  EXPECT_NEAR(scale.density, 1000, 1e-6);
  EXPECT_NEAR(scale.mass, s->total_mass(), 1e-9);
  EXPECT_NEAR(scale.mass, 1000 * s->rest_volume(), 1e-6);
}

TEST(LoadBoundsTest, AbsurdLoadsAreRefusedWithTheBoundAndChangeNothing) {
  std::unique_ptr<Solid> s = Cube(1e6);
  ASSERT_NE(s, nullptr);
  const std::string before = s->SaveState();
  // L = 2 sqrt 3 m, E = 1e6 Pa: a force moves it about F / (E L), so the
  // largest force is 10 E L^2 = 1.2e8 N.
  const absl::StatusOr<int64_t> huge = s->AddPointForce(Force(-1e30));
  ASSERT_FALSE(huge.ok());
  EXPECT_EQ(huge.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(huge.status().message()),
              HasSubstr("point_force.force: 1e+30 N is far beyond what this solid can take"));
  EXPECT_THAT(std::string(huge.status().message()), HasSubstr("the largest this solid takes is 1.2e+08 N"));
  EXPECT_FALSE(s->AddPointForce(Force(1e300)).ok());
  // Pressure: P L / E, at most 10 E = 1e7 Pa.
  const absl::StatusOr<int64_t> press = s->AddPressure(Press(1e12));
  ASSERT_FALSE(press.ok());
  EXPECT_THAT(std::string(press.status().message()),
              HasSubstr("pressure.pascals: 1e+12 Pa is far beyond"));
  EXPECT_THAT(std::string(press.status().message()), HasSubstr("largest this solid takes is 1e+07 Pa"));
  // Gravity: rho g L^2 / E, at most 10 E / (rho L) = 2887 m/s^2.
  const absl::Status g = s->SetGravity(Gravity(-1e6));
  ASSERT_FALSE(g.ok());
  EXPECT_THAT(std::string(g.message()), HasSubstr("gravity: 1e+06 m/s^2 is far beyond"));
  EXPECT_THAT(std::string(g.message()), HasSubstr("largest this solid takes is 2.89e+03 m/s^2"));
  EXPECT_EQ(s->SaveState(), before) << "a refused load changed the solid";
}

TEST(LoadBoundsTest, LoadsTooSmallToMoveAnythingAreRefused) {
  std::unique_ptr<Solid> s = Cube(1e6);
  ASSERT_NE(s, nullptr);
  const std::string before = s->SaveState();
  const absl::StatusOr<int64_t> tiny = s->AddPointForce(Force(1e-300));
  ASSERT_FALSE(tiny.ok());
  EXPECT_THAT(std::string(tiny.status().message()),
              HasSubstr("point_force.force: 1e-300 N would have no effect in double precision"));
  EXPECT_FALSE(s->AddPressure(Press(1e-290)).ok());
  EXPECT_FALSE(s->SetGravity(Gravity(-1e-300)).ok());
  EXPECT_EQ(s->SaveState(), before);
  // Zero is "off": gravity 0 passes.
  EXPECT_OK(s->SetGravity(Gravity(0)));
}

TEST(LoadBoundsTest, OrdinaryLoadsPassAndTheBoundScalesWithStiffness) {
  std::unique_ptr<Solid> soft = Cube(1e6);
  std::unique_ptr<Solid> stiff = Cube(1e9);
  ASSERT_NE(soft, nullptr);
  ASSERT_NE(stiff, nullptr);
  EXPECT_OK(soft->AddPointForce(Force(-100)));
  EXPECT_OK(soft->AddPressure(Press(3000)));
  EXPECT_OK(soft->SetGravity(Gravity(-9.81)));
  for (int k = 0; k < 20; ++k) ASSERT_OK(soft->Step());
  // 1e9 N: beyond the soft cube (1.2e8 N), within the stiff one (1.2e11 N).
  EXPECT_FALSE(soft->AddPointForce(Force(-1e9)).ok());
  EXPECT_OK(stiff->AddPointForce(Force(-1e9)));
}

TEST(LoadBoundsTest, ASceneWithAnAbsurdLoadIsRefusedNamingItsField) {
  for (const auto& [loads, message] :
       {std::pair<std::string, std::string>{
            "point_forces { position { x: 1 y: 1 z: 2 } force { z: -1e30 } }",
            "loads.point_forces[0].force: 1e+30 N is far beyond"},
        {"gravity { z: -1e9 }", "loads.gravity: 1e+09 m/s^2 is far beyond"}}) {
    const absl::StatusOr<Scene> scene = scene::ParseScene(absl::StrCat(R"pb(
      name: "cube"
      mesh { block { nx: 2 ny: 2 nz: 2 } }
      materials { base { young_modulus: 1e6 density: 1000 } }
      loads { )pb",
                                                                   loads, " }"),
                                                      "test");
    ASSERT_OK(scene);
    auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(), std::nullopt);
    ASSERT_OK(d);
    const absl::StatusOr<std::unique_ptr<Solid>> s = Solid::Create(*scene, *std::move(d), 1);
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(std::string(s.status().message()), HasSubstr(message));
  }
}

}  // namespace
}  // namespace dynsolid::solid
