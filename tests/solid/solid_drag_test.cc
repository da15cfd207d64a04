// Drags and curve manipulation (solid.h AddDrag, AddCurveDrag, MoveDrag):
// springs from material points to targets a client moves.
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/solid/solid_support.h"

namespace dynsolid::solid {
namespace {

const char* kStandingBlock = R"pb(
  mesh { block { nx: 2 ny: 2 nz: 2 } }
  subdivision { levels: 1 }
  materials { base { young_modulus: 1e4 density: 100 } }
  constraints { fixed { box { min { x: -1 y: -1 z: -0.01 } max { x: 3 y: 3 z: 0.01 } } } }
  solver { time_step: 1e-3 }
)pb";

TEST(SolidDragTest, ASoftDragAcceleratesAFreeSolidAtItsSpringForceOverTheMass) {
  auto s = Make(kFreeBlock);
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d c0 = Centre(*s);
  // Grip (1, 1, 2), target 1 m above: F = k * 1 m = 10 N up, nearly
  // constant while the solid moves a fraction of a millimetre.
  ASSERT_OK_AND_ASSIGN(int64_t id, s->AddDrag(Parse<Drag>(
      "material_point { x: 1 y: 1 z: 1.5 } target { x: 1 y: 1 z: 2.5 } stiffness: 10")));
  EXPECT_GT(id, 0);
  const int n = 200;
  for (int i = 0; i < n; ++i) ASSERT_OK(s->Step());
  // Central differences from rest under a constant acceleration a move the
  // centre by a h^2 n (n + 1) / 2 in n steps.
  const double h = s->time_step();
  const double a = 10.0 / s->total_mass();
  const double expected = a * h * h * n * (n + 1) / 2;
  const Eigen::Vector3d moved = Centre(*s) - c0;
  EXPECT_NEAR(moved.z(), expected, 1e-3 * expected) << "total mass " << s->total_mass();
  EXPECT_NEAR(moved.x(), 0, 1e-9);
  EXPECT_NEAR(moved.y(), 0, 1e-9);
}

TEST(SolidDragTest, ADragMovesThePickedMaterialPointTowardsItsTarget) {
  auto s = Make(kStandingBlock);
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d grip(1.8, 1, 1.8);
  const Eigen::Vector3d target(2.2, 1, 2.0);
  ASSERT_OK_AND_ASSIGN(std::vector<Eigen::Vector3d> x0, s->MaterialPositions({grip}));
  EXPECT_NEAR((x0[0] - grip).norm(), 0, 1e-12);
  ASSERT_OK_AND_ASSIGN(int64_t id, s->AddDrag(Parse<Drag>(
      "material_point { x: 1.8 y: 1 z: 1.8 } target { x: 2.2 y: 1 z: 2.0 } stiffness: 2e4")));
  for (int i = 0; i < 400; ++i) ASSERT_OK(s->Step());
  ASSERT_OK_AND_ASSIGN(std::vector<Eigen::Vector3d> x1, s->MaterialPositions({grip}));
  const double before = (x0[0] - target).norm(), after = (x1[0] - target).norm();
  EXPECT_LT(after, 0.7 * before) << "the grip moved from " << x0[0].transpose() << " to "
                                 << x1[0].transpose();
  EXPECT_GT((x1[0] - x0[0]).dot(target - grip), 0);
  // Moving the target the other way pulls it back; releasing lets it go.
  ASSERT_OK(s->MoveDrag(id, {Eigen::Vector3d(1.6, 1, 1.8)}));
  for (int i = 0; i < 400; ++i) ASSERT_OK(s->Step());
  ASSERT_OK_AND_ASSIGN(std::vector<Eigen::Vector3d> x2, s->MaterialPositions({grip}));
  EXPECT_LT(x2[0].x(), x1[0].x());
  ASSERT_OK(s->RemoveLoad(id));
  EXPECT_TRUE(s->load_ids().empty());
  EXPECT_THAT(s->MoveDrag(id, {target}), StatusIs(absl::StatusCode::kNotFound));
}

TEST(SolidDragTest, ACurvePullsItsSampledPointsTowardsTheTargetPolyline) {
  auto s = Make(kStandingBlock);
  ASSERT_NE(s, nullptr);
  ASSERT_OK_AND_ASSIGN(int64_t id, s->AddCurveDrag(Parse<CurveDrag>(R"pb(
      material_points { x: 0.2 y: 1 z: 1.8 } material_points { x: 1.8 y: 1 z: 1.8 }
      targets { x: 0.2 y: 1 z: 1.8 } targets { x: 1.8 y: 1 z: 2.3 }
      stiffness: 2e4 samples: 8)pb")));
  std::vector<Eigen::Vector3d> line;
  for (int k = 0; k < 8; ++k) line.emplace_back(0.2 + 1.6 * k / 7.0, 1, 1.8);
  for (int i = 0; i < 400; ++i) ASSERT_OK(s->Step());
  ASSERT_OK_AND_ASSIGN(std::vector<Eigen::Vector3d> x, s->MaterialPositions(line));
  // The far end is lifted more than the near one: the solid bends.
  EXPECT_GT(x[7].z() - 1.8, 0.05);
  EXPECT_GT(x[7].z(), x[0].z() + 0.05);
  // A curve's targets move as a polyline of as many points as it started with.
  EXPECT_THAT(s->MoveDrag(id, {Eigen::Vector3d(0, 0, 0)}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("takes 2 points")));
  ASSERT_OK(s->MoveDrag(id, {Eigen::Vector3d(0.2, 1, 1.8), Eigen::Vector3d(1.8, 1, 1.8)}));
}

TEST(SolidDragTest, BadDragsAreRefusedByNameAndChangeNothing) {
  auto s = Make(kStandingBlock);
  ASSERT_NE(s, nullptr);
  for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
  const std::string before = s->SaveState();
  EXPECT_THAT(s->AddDrag(Parse<Drag>(
                  "material_point { x: 5 y: 1 z: 1 } target { x: 1 y: 1 z: 3 } stiffness: 10")),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("drag.material_point: point (5, 1, 1) is not inside")));
  EXPECT_THAT(s->AddDrag(Parse<Drag>(
                  "material_point { x: 1 y: 1 z: 1 } target { x: 1 y: 1 z: 3 } stiffness: 0")),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("drag.stiffness")));
  EXPECT_THAT(s->AddDrag(Parse<Drag>(
                  "material_point { x: 1 y: 1 z: 1 } target { x: nan y: 1 z: 3 } stiffness: 1")),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("drag.target.x")));
  EXPECT_THAT(s->AddCurveDrag(Parse<CurveDrag>(
                  "material_points { x: 1 y: 1 z: 1 } targets { x: 1 y: 1 z: 1 } stiffness: 1")),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("curve.material_points")));
  EXPECT_THAT(s->MoveDrag(99, {Eigen::Vector3d(0, 0, 0)}), StatusIs(absl::StatusCode::kNotFound));
  EXPECT_EQ(s->SaveState(), before);
}

TEST(SolidDragTest, SavedDragsRestoreAndContinueBitForBit) {
  std::unique_ptr<Solid> a, b;
  ASSERT_NO_FATAL_FAILURE(MakeTwins(kStandingBlock, &a, &b));
  ASSERT_OK_AND_ASSIGN(int64_t id, a->AddDrag(Parse<Drag>(
      "material_point { x: 1.8 y: 1 z: 1.8 } target { x: 2.2 y: 1 z: 2.0 } stiffness: 2e4")));
  ASSERT_OK(a->AddCurveDrag(Parse<CurveDrag>(R"pb(
      material_points { x: 0.2 y: 0.5 z: 1.8 } material_points { x: 1.8 y: 0.5 z: 1.8 }
      targets { x: 0.2 y: 0.5 z: 1.9 } targets { x: 1.8 y: 0.5 z: 2.3 } stiffness: 1e4)pb")));
  for (int i = 0; i < 20; ++i) ASSERT_OK(a->Step());
  ASSERT_OK(a->MoveDrag(id, {Eigen::Vector3d(2.5, 1.2, 2.2)}));
  ASSERT_OK(b->RestoreState(a->SaveState()));
  EXPECT_EQ(b->load_ids(), a->load_ids());
  for (int i = 0; i < 20; ++i) {
    ASSERT_OK(a->Step());
    ASSERT_OK(b->Step());
  }
  EXPECT_EQ(b->SaveState(), a->SaveState());
}

}  // namespace
}  // namespace dynsolid::solid

namespace dynsolid::solid {
namespace {

// The brush's falloff (MaterialPaint.falloff): a hard brush reaches the
// target deeper inside its ball than a soft one.
TEST(SolidBrushTest, AHardBrushPaintsMoreOfItsBallThanASoftOne) {
  const std::string paint =
      "region { sphere { center { x: 1 y: 1 z: 2 } radius: 0.9 } } material { young_modulus: "
      "1e6 } strength: 1 falloff: ";
  auto stiffness_at_top = [&](const std::string& falloff) {
    auto s = Make(kStandingBlock);
    EXPECT_OK(s->PaintMaterial(Parse<MaterialPaint>(paint + falloff)));
    const Points x = s->SurfacePositions();
    const Solid::SurfaceFields f = s->ComputeSurfaceFields();
    int best = 0;
    for (int v = 1; v < x.rows(); ++v) {
      if ((x.row(v) - Eigen::RowVector3d(1, 1, 2)).norm() <
          (x.row(best) - Eigen::RowVector3d(1, 1, 2)).norm()) {
        best = v;
      }
    }
    return f.stiffness[best];
  };
  const double hard = stiffness_at_top("0.05"), soft = stiffness_at_top("1");
  EXPECT_GT(hard, 0.9e6);
  EXPECT_LT(soft, 0.9 * hard);
  EXPECT_GT(soft, 1e4);
  auto s = Make(kStandingBlock);
  const std::string before = s->SaveState();
  EXPECT_THAT(s->PaintMaterial(Parse<MaterialPaint>(paint + "2")),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("paint.falloff must be in [0, 1]")));
  EXPECT_EQ(s->SaveState(), before);
}

}  // namespace
}  // namespace dynsolid::solid
