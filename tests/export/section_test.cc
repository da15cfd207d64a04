// The cut-away (solver/export/section.h): on a block whose creases keep it
// a box at every level, a plane through it cuts a section of the box's
// cross-section area, facing along the plane's normal; the fields read 0
// at rest, the displacement of a translation everywhere, a stretch's strain
// and distortion exactly; painted moduli show; bad requests are refused
// naming the field.
#include "solver/export/section.h"

#include <cmath>
#include <memory>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::exporter {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

std::unique_ptr<solid::Solid> Box() {
  auto scene = scene::ParseScene(R"pb(
    name: "box"
    mesh { block { nx: 2 ny: 1 nz: 1 } }
    subdivision { levels: 2 }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: 1e5 } }
  )pb", "test");
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, "", std::nullopt);
  EXPECT_OK(d);
  auto s = solid::Solid::Create(*scene, *std::move(d), 1);
  EXPECT_OK(s);
  return *std::move(s);
}

double Area(const Section& s, const Eigen::Vector3d& n, int* facing_away) {
  double area = 0;
  *facing_away = 0;
  for (size_t t = 0; t + 9 <= s.positions.size(); t += 9) {
    const Eigen::Vector3d a(s.positions[t], s.positions[t + 1], s.positions[t + 2]);
    const Eigen::Vector3d b(s.positions[t + 3], s.positions[t + 4], s.positions[t + 5]);
    const Eigen::Vector3d c(s.positions[t + 6], s.positions[t + 7], s.positions[t + 8]);
    const Eigen::Vector3d m = (b - a).cross(c - a);
    area += 0.5 * m.norm();
    if (m.dot(n) < -1e-12) ++*facing_away;
  }
  return area;
}

TEST(SectionTest, APlaneThroughTheBoxCutsItsCrossSection) {
  const auto s = Box();
  const Points rest = s->discretization().control().positions();
  SectionInput in{&s->discretization(), rest, rest, nullptr};
  // x = 0.7 (the box is [0, 2] x [0, 1] x [0, 1]): 1 m^2; y = 0.3: 2 m^2;
  // a diagonal plane through the middle, normal (1, 0, 1): sqrt(2) m^2.
  struct Case {
    Eigen::Vector3d point, normal;
    double area;
  };
  for (const Case& c : {Case{{0.7, 0, 0}, {1, 0, 0}, 1.0}, Case{{0, 0.3, 0}, {0, 2, 0}, 2.0},
                        Case{{1, 0.5, 0.5}, {1, 0, 1}, std::sqrt(2.0)}}) {
    ASSERT_OK_AND_ASSIGN(Section cut, CutSection(in, c.point, c.normal, "strain"));
    int away = 0;
    const double area = Area(cut, c.normal.normalized(), &away);
    EXPECT_NEAR(area, c.area, 1e-6 * c.area) << c.normal.transpose();
    EXPECT_EQ(away, 0) << "triangles face along the normal";
    EXPECT_GT(cut.cells_cut, 0);
    EXPECT_EQ(cut.values.size() * 3, cut.positions.size());
    EXPECT_EQ(cut.max, 0.0) << "no strain at rest";
  }
  // A plane beside the box cuts nothing.
  ASSERT_OK_AND_ASSIGN(Section none, CutSection(in, {5, 0, 0}, {1, 0, 0}, "strain"));
  EXPECT_TRUE(none.positions.empty());
  EXPECT_EQ(none.cells_cut, 0);
}

TEST(SectionTest, FieldsOfATranslationAndAStretch) {
  const auto s = Box();
  const Points rest = s->discretization().control().positions();
  Points moved = rest;
  moved.rowwise() += Eigen::RowVector3d(0.3, 0.4, 0);  // 0.5 m
  SectionInput in{&s->discretization(), moved, rest, nullptr};
  ASSERT_OK_AND_ASSIGN(Section d, CutSection(in, {1.3, 0, 0}, {1, 0, 0}, "displacement"));
  EXPECT_EQ(d.unit, "m");
  EXPECT_NEAR(d.min, 0.5, 1e-6);
  EXPECT_NEAR(d.max, 0.5, 1e-6);
  ASSERT_OK_AND_ASSIGN(Section t, CutSection(in, {1.3, 0, 0}, {1, 0, 0}, "distortion"));
  EXPECT_LT(t.max, 1e-6) << "a translation does not distort";
  // Stretched 10 % along x: every cell's x edges grow by 10 %; its best
  // fit F = diag(1.1, 1, 1): distortion 1 - 1 / 1.1.
  Points stretched = rest;
  stretched.col(0) *= 1.1;
  in.positions = stretched;
  ASSERT_OK_AND_ASSIGN(Section e, CutSection(in, {1.0, 0.5, 0.5}, {0, 0, 1}, "strain"));
  EXPECT_NEAR(e.min, 0.1, 1e-6);
  EXPECT_NEAR(e.max, 0.1, 1e-6);
  ASSERT_OK_AND_ASSIGN(Section f, CutSection(in, {1.0, 0.5, 0.5}, {0, 0, 1}, "distortion"));
  EXPECT_NEAR(f.min, 1 - 1 / 1.1, 1e-6);
  EXPECT_NEAR(f.max, 1 - 1 / 1.1, 1e-6);
}

TEST(SectionTest, PaintedStiffnessShows) {
  auto s = Box();
  MaterialPaint paint;
  paint.mutable_region()->mutable_sphere()->mutable_center()->set_x(2);
  paint.mutable_region()->mutable_sphere()->set_radius(0.8);
  paint.mutable_material()->set_young_modulus(1e6);
  paint.set_strength(1);
  ASSERT_OK(s->PaintMaterial(paint));
  ASSERT_OK_AND_ASSIGN(MaterialFields m, MaterialFieldsOf(s->discretization(), s->SaveDesign()));
  const Points rest = s->discretization().control().positions();
  SectionInput in{&s->discretization(), rest, rest, &m};
  ASSERT_OK_AND_ASSIGN(Section k, CutSection(in, {1, 0.5, 0.5}, {0, 1, 0}, "stiffness"));
  EXPECT_EQ(k.unit, "Pa");
  EXPECT_NEAR(k.min, 1e5, 1.0);
  EXPECT_GT(k.max, 5e5) << "the painted corner";
  EXPECT_LE(k.max, 1e6 * (1 + 1e-6));
}

TEST(SectionTest, BadRequestsAreRefusedNamingTheField) {
  const auto s = Box();
  const Points rest = s->discretization().control().positions();
  SectionInput in{&s->discretization(), rest, rest, nullptr};
  EXPECT_THAT(CutSection(in, {1, 0, 0}, {0, 0, 0}, "strain").status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("normal: must be finite and not zero")));
  EXPECT_THAT(CutSection(in, {NAN, 0, 0}, {1, 0, 0}, "strain").status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("point: not finite")));
  EXPECT_THAT(CutSection(in, {1, 0, 0}, {1, 0, 0}, "stress").status(),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("field: \"stress\" is not one of strain, displacement, stiffness, distortion")));
  EXPECT_THAT(CutSection(in, {1, 0, 0}, {1, 0, 0}, "stiffness").status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("stiffness needs")));
}

}  // namespace
}  // namespace dynsolid::exporter
