// Haptic contact (solid.h "Haptic contact", docs/model.md 9): the closest point
// of the surface, the local response at it, and contact loads.
#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::solid {
namespace {

using ::dynsolid::testing::StatusIs;

std::unique_ptr<Solid> MakeScene(const Scene& scene, std::optional<int> levels) {
  auto d = scene::BuildDiscretization(scene, scene::BuiltinSceneDir(), levels);
  EXPECT_OK(d);
  if (!d.ok()) return nullptr;
  auto s = Solid::Create(scene, *std::move(d));
  EXPECT_OK(s);
  return s.ok() ? *std::move(s) : nullptr;
}

// block3 (3 m cube on the ground, local-frame model) at `levels`.
std::unique_ptr<Solid> Block3(int levels) {
  auto scene = scene::BuiltinScene("block3");
  EXPECT_OK(scene);
  return scene.ok() ? MakeScene(*scene, levels) : nullptr;
}

// block3 with the corotational model (its K is the assembled A^T K A).
std::unique_ptr<Solid> Block3Corotational(int levels) {
  auto scene = scene::BuiltinScene("block3");
  EXPECT_OK(scene);
  if (!scene.ok()) return nullptr;
  scene->mutable_solver()->set_model(SolverSettings::COROTATIONAL);
  return MakeScene(*scene, levels);
}

using ::dynsolid::testing::Parse;

void ExpectNear(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol,
                const std::string& what) {
  EXPECT_LT((a - b).norm(), tol) << what << ": got (" << a.transpose() << "), expected ("
                                 << b.transpose() << ")";
}

// At rest block3's boundary is exactly the box [0, 3]^3 (its faces are
// planar and its edges sharp), so closest points and normals are known.
TEST(SolidContactTest, ClosestPointAndNormalOnBlock3AreTheBoxs) {
  auto s = Block3(2);
  ASSERT_NE(s, nullptr);
  struct Case {
    Eigen::Vector3d probe, point, normal;
    double distance;
  };
  const Case cases[] = {
      {{1.3, 1.7, 3.5}, {1.3, 1.7, 3.0}, {0, 0, 1}, 0.5},    // above the top face
      {{1.3, 1.7, 2.9}, {1.3, 1.7, 3.0}, {0, 0, 1}, -0.1},   // just inside under it
      {{3.2, 1.0, 1.5}, {3.0, 1.0, 1.5}, {1, 0, 0}, 0.2},    // beside the +x face
      {{0.4, -0.3, 2.2}, {0.4, 0.0, 2.2}, {0, -1, 0}, 0.3},  // beside the -y face
      {{2.71, 0.37, 3.05}, {2.71, 0.37, 3.0}, {0, 0, 1}, 0.05},
  };
  for (const Case& c : cases) {
    ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint p, s->ClosestSurfacePoint(c.probe));
    ExpectNear(p.point, c.point, 1e-9, "closest point");
    ExpectNear(p.material_point, c.point, 1e-9, "material point (rest = current)");
    ExpectNear(p.normal, c.normal, 1e-9, "normal");
    EXPECT_NEAR(p.distance, c.distance, 1e-9) << "signed distance";
    // The same point by its quad coordinates.
    ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint q, s->SurfacePointAt(p.quad, p.u, p.v));
    ExpectNear(q.point, p.point, 1e-12, "SurfacePointAt");
  }
  // Beyond a corner: the corner itself.
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint corner,
                       s->ClosestSurfacePoint(Eigen::Vector3d(3.5, 3.5, 3.5)));
  ExpectNear(corner.point, Eigen::Vector3d(3, 3, 3), 1e-9, "corner");
  EXPECT_THAT(s->ClosestSurfacePoint(Eigen::Vector3d(NAN, 0, 0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s->SurfacePointAt(-1, 0, 0), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s->SurfacePointAt(0, 1.5, 0), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(SolidContactTest, ResponseSplitsExactlyAndIsStifferThanStatic) {
  auto s = Block3(1);
  ASSERT_NE(s, nullptr);
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint c,
                       s->ClosestSurfacePoint(Eigen::Vector3d(1.5, 1.5, 3.1)));
  for (double tau : {0.01, 0.03, 0.1}) {
    ASSERT_OK_AND_ASSIGN(Solid::ContactResponse r, s->ContactResponseAt(c, tau));
    // W symmetric positive definite.
    EXPECT_LT((r.compliance - r.compliance.transpose()).norm(), 1e-12 * r.compliance.norm());
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(r.compliance).eigenvalues().minCoeff(),
              0)
        << "W at tau " << tau;
    // k = m / tau^2 + b / tau + elastic (the Ritz split is exact).
    const double sum = r.mass / (tau * tau) + r.damping / tau + r.elastic;
    EXPECT_NEAR(sum, r.stiffness, 1e-8 * r.stiffness) << "tau " << tau;
    EXPECT_GT(r.mass, 0);
    EXPECT_GT(r.damping, 0);  // block3 is damped
    // Inertia and damping only add: k >= the static stiffness.
    EXPECT_GT(r.static_stiffness, 0);
    EXPECT_GE(r.stiffness, r.static_stiffness);
    std::printf(
        "tau %.3f s: k %.4g N/m (mass %.4g kg, damping %.4g N s/m, elastic %.4g N/m), "
        "static %.4g N/m\n",
        tau, r.stiffness, r.mass, r.damping, r.elastic, r.static_stiffness);
  }
  // A long horizon tends to the static answer.
  ASSERT_OK_AND_ASSIGN(Solid::ContactResponse slow, s->ContactResponseAt(c, 100.0));
  EXPECT_NEAR(slow.stiffness, slow.static_stiffness, 0.02 * slow.static_stiffness);
  EXPECT_LT(slow.velocity.norm(), 1e-12) << "at rest";
}

// The contact stiffness built by ContactCacheJob on another thread while
// the solid steps (with a local-frame model of the job's own), installed,
// answers as the one ContactResponseAt builds itself at the same state; a
// job for a material that changed meanwhile is not installed; without a
// built cache and asked not to build, ContactResponseAt says so.
TEST(SolidContactTest, ContactStiffnessBuiltOffTheLoopAnswersAsTheInlineOne) {
  for (bool corotational : {false, true}) {
    auto a = corotational ? Block3Corotational(1) : Block3(1);
    auto b = corotational ? Block3Corotational(1) : Block3(1);
    ASSERT_NE(a, nullptr);
    ASSERT_NE(b, nullptr);
    for (Solid* s : {a.get(), b.get()}) {
      ASSERT_OK(s->SetGravity(Parse<Vec3>("z: -9.81")));
      for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
    }
    ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint c,
                         b->ClosestSurfacePoint(Eigen::Vector3d(1.2, 1.9, 3.2)));
    EXPECT_TRUE(b->ContactCacheStale());
    EXPECT_THAT(b->ContactResponseAt(c, 0.03, /*build_if_stale=*/false),
                StatusIs(absl::StatusCode::kUnavailable));
    // The job copies the state now; b steps on meanwhile.
    auto job = b->ContactCacheJob();
    absl::StatusOr<std::shared_ptr<Solid::PreparedContact>> built;
    std::thread builder([&] { built = job(); });
    for (int i = 0; i < 5; ++i) ASSERT_OK(b->Step());
    builder.join();
    ASSERT_OK(built);
    ASSERT_TRUE(b->InstallContactCache(*built));
    EXPECT_FALSE(b->ContactCacheStale());
    // The inline build at the state the job copied: a, 5 steps behind.
    ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint ca,
                         a->ClosestSurfacePoint(Eigen::Vector3d(1.2, 1.9, 3.2)));
    ASSERT_OK_AND_ASSIGN(Solid::ContactResponse inline_r, a->ContactResponseAt(ca, 0.03));
    ASSERT_OK_AND_ASSIGN(Solid::ContactResponse job_r,
                         b->ContactResponseAt(ca, 0.03, /*build_if_stale=*/false));
    EXPECT_EQ(job_r.build_ms < 50, true);
    EXPECT_NEAR(job_r.stiffness, inline_r.stiffness, 1e-6 * inline_r.stiffness) << corotational;
    EXPECT_NEAR(job_r.static_stiffness, inline_r.static_stiffness,
                1e-6 * inline_r.static_stiffness)
        << corotational;
    // A job for the material before a paint is refused.
    auto stale_job = b->ContactCacheJob();
    ASSERT_OK(b->PaintMaterial(Parse<MaterialPaint>(
        "region { sphere { center { x: 1.5 y: 1.5 z: 2.5 } radius: 0.8 } } "
        "material { young_modulus: 3e5 } strength: 1")));
    ASSERT_OK_AND_ASSIGN(std::shared_ptr<Solid::PreparedContact> old, stale_job());
    EXPECT_FALSE(b->InstallContactCache(old));
    EXPECT_TRUE(b->ContactCacheStale());
  }
}

// The surface point of `s` nearest `near` and its contact response over
// 0.03 s.
absl::StatusOr<std::pair<Solid::SurfacePoint, Solid::ContactResponse>> ContactNear(
    Solid& s, const Eigen::Vector3d& near) {
  absl::StatusOr<Solid::SurfacePoint> c = s.ClosestSurfacePoint(near);
  if (!c.ok()) return c.status();
  absl::StatusOr<Solid::ContactResponse> r = s.ContactResponseAt(*c, 0.03);
  if (!r.ok()) return r.status();
  return std::make_pair(*c, *r);
}

// The static stiffness is the solid's own: a point force at the material
// point, solved statically (corotational: SolveStaticLinear with the same
// A^T K A), moves the point by F / k_static along the normal.
TEST(SolidContactTest, StaticStiffnessMatchesTheStaticSolution) {
  auto s = Block3Corotational(1);
  ASSERT_NE(s, nullptr);
  ASSERT_OK_AND_ASSIGN(const auto contact, ContactNear(*s, Eigen::Vector3d(1.2, 1.9, 3.2)));
  const auto& [c, r] = contact;
  const double force = 10.0;  // N, into the solid
  PointForce pf;
  pf.mutable_position()->set_x(c.material_point.x());
  pf.mutable_position()->set_y(c.material_point.y());
  pf.mutable_position()->set_z(c.material_point.z());
  pf.mutable_force()->set_z(-force);
  ASSERT_OK(s->AddPointForce(pf));
  ASSERT_OK_AND_ASSIGN(Points p, s->SolveStaticLinear());
  s->SetAtRest(p);
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint moved, s->SurfacePointAt(c.quad, c.u, c.v));
  const double dent = (c.point - moved.point).dot(c.normal);
  std::printf("static: F %.1f N, dent %.6g m, F / dent %.6g N/m, k_static %.6g N/m\n", force, dent,
              force / dent, r.static_stiffness);
  EXPECT_NEAR(force / dent, r.static_stiffness, 1e-6 * r.static_stiffness);
}

// Painting half the block ten times stiffer raises the stiffness felt
// there (static and over the horizon) much more than on the other half. (A
// small painted patch changes a point's static stiffness little: the
// whole soft block deforms under a push.)
TEST(SolidContactTest, PaintedStifferRegionIsFeltStiffer) {
  auto s = Block3(1);
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d soft_probe(0.75, 0.75, 3.05), stiff_probe(2.25, 2.25, 3.05);
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint a, s->ClosestSurfacePoint(soft_probe));
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint b, s->ClosestSurfacePoint(stiff_probe));
  ASSERT_OK_AND_ASSIGN(Solid::ContactResponse a0, s->ContactResponseAt(a, 0.03));
  ASSERT_OK_AND_ASSIGN(Solid::ContactResponse b0, s->ContactResponseAt(b, 0.03));
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(
      "region { box { min { x: 1.5 y: -1 z: -1 } max { x: 4 y: 4 z: 4 } } } falloff: 0.1 "
      "material { young_modulus: 1e6 } strength: 1")));
  ASSERT_OK_AND_ASSIGN(Solid::ContactResponse a1, s->ContactResponseAt(a, 0.03));
  ASSERT_OK_AND_ASSIGN(Solid::ContactResponse b1, s->ContactResponseAt(b, 0.03));
  std::printf(
      "static stiffness: soft point %.4g -> %.4g N/m, painted point %.4g -> %.4g N/m "
      "(x%.2f); at tau 30 ms %.4g -> %.4g and %.4g -> %.4g N/m (elastic part %.4g -> "
      "%.4g)\n",
      a0.static_stiffness, a1.static_stiffness, b0.static_stiffness, b1.static_stiffness,
      b1.static_stiffness / b0.static_stiffness, a0.stiffness, a1.stiffness, b0.stiffness,
      b1.stiffness, b0.elastic, b1.elastic);
  EXPECT_GT(b1.static_stiffness, 3.0 * b0.static_stiffness);
  EXPECT_GT(b1.stiffness, 1.2 * b0.stiffness);
  EXPECT_GT(b1.elastic, 2.0 * b0.elastic);
  EXPECT_GT(b1.static_stiffness, 2.0 * a1.static_stiffness);
}

Eigen::Vector3d PointNow(const Solid& s, const Solid::SurfacePoint& c) {
  auto p = s.SurfacePointAt(c.quad, c.u, c.v);
  EXPECT_OK(p);
  return p.ok() ? p->point : Eigen::Vector3d::Zero();
}

// A contact load is the same load as a point force at the material point.
TEST(SolidContactTest, ContactLoadActsLikeAPointForceAtTheMaterialPoint) {
  auto a = Block3(1), b = Block3(1);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  ASSERT_OK_AND_ASSIGN(Solid::SurfacePoint c,
                       a->ClosestSurfacePoint(Eigen::Vector3d(1.1, 2.3, 3.1)));
  const Eigen::Vector3d f(3.0, -2.0, -40.0);
  ASSERT_OK(a->SetContactLoads({{c.quad, c.u, c.v, f}}));
  EXPECT_TRUE(a->has_contact_loads());
  PointForce pf;
  pf.mutable_position()->set_x(c.material_point.x());
  pf.mutable_position()->set_y(c.material_point.y());
  pf.mutable_position()->set_z(c.material_point.z());
  pf.mutable_force()->set_x(f.x());
  pf.mutable_force()->set_y(f.y());
  pf.mutable_force()->set_z(f.z());
  ASSERT_OK_AND_ASSIGN(const int64_t force_id, b->AddPointForce(pf));
  for (int i = 0; i < 100; ++i) {
    ASSERT_OK(a->Step());
    ASSERT_OK(b->Step());
  }
  const Points diff = a->control_positions() - b->control_positions();
  const Points moved = a->control_positions() - b->discretization().control().positions();
  EXPECT_LT(diff.norm(), 1e-9 * moved.norm()) << "contact load vs point force";
  EXPECT_GT((c.point - PointNow(*a, c)).dot(c.normal), 0) << "pushed in";
  EXPECT_EQ(a->rollbacks(), 0);
  // Not part of the state: a restored solid has none.
  const std::string state = a->SaveState();
  auto r = Block3(1);
  ASSERT_OK(r->RestoreState(state));
  EXPECT_FALSE(r->has_contact_loads());
  // Removing it: the set is empty, the carried forces lose it.
  ASSERT_OK(a->SetContactLoads({}));
  EXPECT_FALSE(a->has_contact_loads());
  ASSERT_OK(b->RemoveLoad(force_id));
  for (int i = 0; i < 50; ++i) {
    ASSERT_OK(a->Step());
    ASSERT_OK(b->Step());
  }
  EXPECT_LT((a->control_positions() - b->control_positions()).norm(), 1e-9 * moved.norm());
}

TEST(SolidContactTest, BadContactLoadsChangeNothing) {
  auto s = Block3(1);
  ASSERT_NE(s, nullptr);
  ASSERT_OK(s->Step());
  const std::string before = s->SaveState();
  EXPECT_THAT(s->SetContactLoads({{-1, 0, 0, Eigen::Vector3d(0, 0, 1)}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s->SetContactLoads({{0, 0.5, 2.0, Eigen::Vector3d(0, 0, 1)}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s->SetContactLoads({{0, 0.5, 0.5, Eigen::Vector3d(0, NAN, 1)}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_FALSE(s->has_contact_loads());
  EXPECT_EQ(s->SaveState(), before);
}

// The local-frame model's stiffness (finite differences of its own forces)
// predicts its quasi-static dent: a small contact load held until the
// damped block settles moves the point by F / k_static.
TEST(SolidContactTest, LocalFrameStaticStiffnessPredictsTheSettledDent) {
  auto s = Block3(1);
  ASSERT_NE(s, nullptr);
  ASSERT_OK_AND_ASSIGN(const auto contact, ContactNear(*s, Eigen::Vector3d(1.5, 1.5, 3.1)));
  const auto& [c, r] = contact;
  const double force = 20.0;
  ASSERT_OK(s->SetContactLoads({{c.quad, c.u, c.v, -force * c.normal}}));
  for (int i = 0; i < 4000; ++i) ASSERT_OK(s->Step());
  const double dent = (c.point - PointNow(*s, c)).dot(c.normal);
  std::printf(
      "local frame: F %.1f N, settled dent %.6g m, F / dent %.6g N/m, k_static %.6g "
      "N/m\n",
      force, dent, force / dent, r.static_stiffness);
  EXPECT_NEAR(force / dent, r.static_stiffness, 0.03 * r.static_stiffness);
}

}  // namespace
}  // namespace dynsolid::solid
