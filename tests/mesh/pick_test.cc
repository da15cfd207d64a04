// Ray picking on quad surfaces.
#include "solver/mesh/pick.h"

#include <cmath>

#include <Eigen/Geometry>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/testing/status_matchers.h"

namespace dynsolid::mesh {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;
using Vec = Eigen::Vector3d;

// The unit cube's six faces as outward quads; vertex i has bits (x, y, z).
struct Cube {
  Points p;
  std::vector<std::array<int32_t, 4>> quads;
  Cube() {
    p.resize(8, 3);
    for (int i = 0; i < 8; ++i) p.row(i) << (i & 1), (i >> 1) & 1, (i >> 2) & 1;
    quads = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  }
};

TEST(PickTest, HitsTheTopFaceAtTheRightParameters) {
  const Cube cube;
  absl::StatusOr<PickHit> hit =
      PickQuads(cube.quads, cube.p, {Vec(0.25, 0.75, 5.0), Vec(0, 0, -2)});
  ASSERT_TRUE(hit.ok()) << hit.status();
  EXPECT_EQ(hit->quad, 1) << "the +z quad (4 5 7 6), nearer than the -z one";
  EXPECT_NEAR(hit->distance, 4.0, 1e-14);
  EXPECT_LT((hit->point - Vec(0.25, 0.75, 1.0)).norm(), 1e-14);
  // Quad (4 5 7 6): a = (0,0,1), b = (1,0,1), d = (0,1,1): s = x, t = y.
  EXPECT_NEAR(hit->s, 0.25, 1e-12);
  EXPECT_NEAR(hit->t, 0.75, 1e-12);
  EXPECT_LT((BilinearPoint(cube.quads[1], cube.p, hit->s, hit->t) - hit->point).norm(), 1e-12);
}

TEST(PickTest, MissReturnsNotFound) {
  const Cube cube;
  EXPECT_THAT(PickQuads(cube.quads, cube.p, {Vec(2, 2, 5), Vec(0, 0, -1)}),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("ray misses the surface")));
  EXPECT_THAT(PickQuads(cube.quads, cube.p, {Vec(0.5, 0.5, 5), Vec(0, 0, 1)}),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("ray misses")))
      << "the cube is behind the origin";
}

TEST(PickTest, NearestOfTwoHitsWhateverTheirOrder) {
  // Two parallel unit squares at z = 0 and z = 2; the far one listed first.
  Points p(8, 3);
  p << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 2, 1, 0, 2, 1, 1, 2, 0, 1, 2;
  const std::vector<std::array<int32_t, 4>> quads = {{4, 5, 6, 7}, {0, 1, 2, 3}};
  absl::StatusOr<PickHit> up = PickQuads(quads, p, {Vec(0.5, 0.5, -1), Vec(0, 0, 1)});
  ASSERT_TRUE(up.ok()) << up.status();
  EXPECT_EQ(up->quad, 1);
  EXPECT_NEAR(up->distance, 1.0, 1e-14);
  absl::StatusOr<PickHit> down = PickQuads(quads, p, {Vec(0.5, 0.5, 3), Vec(0, 0, -1)});
  ASSERT_TRUE(down.ok()) << down.status();
  EXPECT_EQ(down->quad, 0);
  EXPECT_NEAR(down->distance, 1.0, 1e-14);
}

TEST(PickTest, FromInsideHitsTheFarSide) {
  const Cube cube;
  absl::StatusOr<PickHit> hit = PickQuads(cube.quads, cube.p, {Vec(0.5, 0.3, 0.5), Vec(1, 0, 0)});
  ASSERT_TRUE(hit.ok()) << hit.status();
  EXPECT_EQ(hit->quad, 5) << "the +x quad";
  EXPECT_NEAR(hit->distance, 0.5, 1e-14);
}

TEST(PickTest, RejectsBadRays) {
  const Cube cube;
  EXPECT_THAT(PickQuads(cube.quads, cube.p, {Vec(NAN, 0, 0), Vec(1, 0, 0)}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("ray.origin")));
  EXPECT_THAT(PickQuads(cube.quads, cube.p, {Vec(0, 0, 0), Vec(0, 0, 0)}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("ray.direction")));
  EXPECT_THAT(PickQuads(cube.quads, cube.p, {Vec(0, 0, 0), Vec(INFINITY, 0, 0)}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("ray.direction")));
  std::vector<std::array<int32_t, 4>> bad = {{0, 1, 2, 9}};
  EXPECT_THAT(PickQuads(bad, cube.p, {Vec(0, 0, 5), Vec(0, 0, -1)}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("quads[0]: vertex 9")));
}

TEST(PickTest, InverseBilinearOnAPlanarTrapezoid) {
  // A planar, non-parallelogram quad, tilted: the bilinear map is not affine.
  Points p(4, 3);
  p << 0, 0, 0, 4, 0, 0, 3, 2, 0, 0.5, 1.5, 0;
  Eigen::Matrix3d r = Eigen::AngleAxisd(0.4, Vec(1, 2, 3).normalized()).toRotationMatrix();
  p = p * r.transpose();
  const std::vector<std::array<int32_t, 4>> quads = {{0, 1, 2, 3}};
  const Vec normal = r * Vec(0, 0, 1);
  for (double s : {0.1, 0.37, 0.5, 0.93}) {
    for (double t : {0.05, 0.44, 0.8}) {
      const Vec target = BilinearPoint(quads[0], p, s, t);
      absl::StatusOr<PickHit> hit = PickQuads(
          quads, p,
          {target + 3.0 * normal + 0.2 * r * Vec(1, 0, 0), -3.0 * normal - 0.2 * r * Vec(1, 0, 0)});
      ASSERT_TRUE(hit.ok()) << hit.status();
      EXPECT_NEAR(hit->s, s, 1e-9) << "t " << t;
      EXPECT_NEAR(hit->t, t, 1e-9) << "s " << s;
      EXPECT_LT((BilinearPoint(quads[0], p, hit->s, hit->t) - hit->point).norm(), 1e-9 * 4.0);
    }
  }
}

TEST(PickTest, TriangleAsDegenerateQuad) {
  Points p(3, 3);
  p << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  const std::vector<std::array<int32_t, 4>> quads = {{0, 1, 2, 2}};
  absl::StatusOr<PickHit> hit = PickQuads(quads, p, {Vec(0.2, 0.3, 1), Vec(0, 0, -1)});
  ASSERT_TRUE(hit.ok()) << hit.status();
  EXPECT_LT((BilinearPoint(quads[0], p, hit->s, hit->t) - Vec(0.2, 0.3, 0)).norm(), 1e-9);
  EXPECT_FALSE(PickQuads(quads, p, {Vec(0.8, 0.8, 1), Vec(0, 0, -1)}).ok());
}

}  // namespace
}  // namespace dynsolid::mesh
