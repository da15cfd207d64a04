// Runtime edits of a live solid (loads, constraints), invalid calls, and
// the boundary surface for watchers. Material painting, exact
// save/restore and prepared changes: solid_paint_test.cc.
#include <cmath>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/solid/solid_support.h"

namespace dynsolid::solid {
namespace {

// Volume enclosed by the boundary quads (each split into two triangles).
double EnclosedVolume(const Solid& s) {
  const Points x = s.SurfacePositions();
  double v = 0;
  for (const auto& q : s.BoundarySurface().quads) {
    const Eigen::Vector3d a = x.row(q[0]), b = x.row(q[1]), c = x.row(q[2]), d = x.row(q[3]);
    v += a.dot(b.cross(c)) / 6.0 + a.dot(c.cross(d)) / 6.0;
  }
  return v;
}

TEST(SolidRuntimeTest, PointForceAddedAtRuntimeAcceleratesAFreeSolidAtFOverM) {
  auto s = Make(kFreeBlock);
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d c0 = Centre(*s);
  ASSERT_OK(s->AddPointForce(
      Parse<PointForce>("position { x: 0.7 y: 1.2 z: 1.0 } force { x: 40 y: 0 z: -10 }")));
  const int n = 200;
  for (int i = 0; i < n; ++i) ASSERT_OK(s->Step());
  const double h = s->time_step();
  const Eigen::Vector3d want = Eigen::Vector3d(40, 0, -10) / s->total_mass() * h * h * n * (n + 1) / 2.0;
  const Eigen::Vector3d got = Centre(*s) - c0;
  EXPECT_NEAR((got - want).norm(), 0.0, 1e-8 * want.norm())
      << "centre of mass moved " << got.transpose() << ", F/m predicts " << want.transpose();
  EXPECT_EQ(s->rollbacks(), 0);
}

TEST(SolidRuntimeTest, GravityAcceleratesAFreeSolidAtG) {
  auto s = Make(kFreeBlock);
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d c0 = Centre(*s);
  ASSERT_OK(s->SetGravity(Parse<Vec3>("x: 1 z: -9.81")));
  EXPECT_EQ(s->gravity(), Eigen::Vector3d(1, 0, -9.81));
  const int n = 100;
  for (int i = 0; i < n; ++i) ASSERT_OK(s->Step());
  const double h = s->time_step();
  const Eigen::Vector3d want = Eigen::Vector3d(1, 0, -9.81) * h * h * n * (n + 1) / 2.0;
  const Eigen::Vector3d got = Centre(*s) - c0;
  EXPECT_NEAR((got - want).norm(), 0.0, 1e-8 * want.norm());
  EXPECT_EQ(s->rollbacks(), 0);
}

TEST(SolidRuntimeTest, RemovingALoadRestoresTheUnloadedTrajectory) {
  std::unique_ptr<Solid> a, b;
  ASSERT_NO_FATAL_FAILURE(MakeTwins(kFreeBlock, &a, &b));
  // b: a point force and a pressure added and removed before any step.
  auto id = b->AddPointForce(Parse<PointForce>("position { x: 1 y: 1 z: 1 } force { x: 5 }"));
  ASSERT_OK(id);
  auto pid = b->AddPressure(Parse<Pressure>(
      "region { sphere { center { x: 1 y: 1 z: 2 } radius: 0.8 } } pascals: 100"));
  ASSERT_OK(pid);
  EXPECT_EQ(*pid, *id + 1) << "ids in call order";
  EXPECT_EQ(b->load_ids(), (std::vector<int64_t>{*id, *pid}));
  ASSERT_OK(b->RemoveLoad(*id));
  ASSERT_OK(b->RemoveLoad(*pid));
  EXPECT_TRUE(b->load_ids().empty());
  for (int i = 0; i < 30; ++i) {
    ASSERT_OK(a->Step());
    ASSERT_OK(b->Step());
  }
  EXPECT_EQ(a->control_positions(), b->control_positions()) << "bit-identical";

  // Loaded for 20 steps, then removed: the free solid's momentum stays.
  auto c = Make(kFreeBlock);
  ASSERT_NE(c, nullptr);
  auto cid = c->AddPointForce(Parse<PointForce>("position { x: 1 y: 1 z: 1 } force { x: 5 }"));
  ASSERT_OK(cid);
  for (int i = 0; i < 20; ++i) ASSERT_OK(c->Step());
  ASSERT_OK(c->RemoveLoad(*cid));
  Eigen::Vector3d previous = Centre(*c), velocity;
  for (int i = 0; i < 40; ++i) {
    ASSERT_OK(c->Step());
    const Eigen::Vector3d now = Centre(*c);
    const Eigen::Vector3d v = (now - previous) / c->time_step();
    if (i == 0) velocity = v;
    EXPECT_NEAR((v - velocity).norm(), 0.0, 1e-11) << "step " << i;  // round-off of positions / h
    previous = now;
  }
  // 20 steps of F/m from rest: x_n = a h^2 n (n + 1) / 2, then x_21 - x_20 = a h^2 20.
  EXPECT_NEAR(velocity.x(), 5.0 / c->total_mass() * c->time_step() * 20, 1e-11);
  EXPECT_THAT(c->RemoveLoad(*cid), StatusIs(absl::StatusCode::kNotFound,
                                            HasSubstr(absl::StrCat("load id ", *cid, " not found"))));
}

TEST(SolidRuntimeTest, UniformPressureOnTheClosedBoundaryHasNoNetForceAndInflates) {
  for (double pascals : {200.0, -200.0}) {
    auto s = Make(R"pb(
      mesh { block { nx: 2 ny: 2 nz: 2 } }
      subdivision { levels: 1 }
      materials { base { young_modulus: 1e4 density: 100 damping: 200 } }
      solver { time_step: 1e-3 }
    )pb");
    ASSERT_NE(s, nullptr);
    const Eigen::Vector3d c0 = Centre(*s);
    const double v0 = EnclosedVolume(*s);
    ASSERT_OK(s->AddPressure(Parse<Pressure>(absl::StrCat(
        "region { box { min { x: -1 y: -1 z: -1 } max { x: 3 y: 3 z: 3 } } } pascals: ",
        pascals))));
    for (int i = 0; i < 300; ++i) ASSERT_OK(s->Step());
    EXPECT_LT((Centre(*s) - c0).norm(), 1e-9) << "no net force: the centre stays";
    const double v = EnclosedVolume(*s);
    if (pascals > 0) {
      EXPECT_GT(v, v0 * 1.001) << "positive pressure inflates";
    } else {
      EXPECT_LT(v, v0 * 0.999) << "negative pressure deflates";
    }
    EXPECT_EQ(s->rollbacks(), 0) << "the pressure's work is in the energy ledger";
  }
}

TEST(SolidRuntimeTest, PressureOnOneFaceHasResultantPressureTimesArea) {
  // Sharp box edges keep the face x = 2 flat and whole: 2 m x 2 m.
  auto s = Make(R"pb(
    mesh { block { nx: 2 ny: 2 nz: 2 } }
    subdivision { levels: 1 }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: 1e4 density: 100 } }
    solver { time_step: 1e-3 cg_tolerance: 1e-13 }
  )pb");
  ASSERT_NE(s, nullptr);
  const Eigen::Vector3d c0 = Centre(*s);
  const double pascals = 300;
  ASSERT_OK(s->AddPressure(Parse<Pressure>(absl::StrCat(
      "region { box { min { x: 1.99 y: -1 z: -1 } max { x: 2.01 y: 3 z: 3 } } } pascals: ",
      pascals))));
  ASSERT_OK(s->Step());
  // One step from rest: x1 - x0 = (F / m) h^2 with F at the rest shape.
  const double h = s->time_step();
  const Eigen::Vector3d want = Eigen::Vector3d(pascals * 4.0, 0, 0) / s->total_mass() * h * h;
  const Eigen::Vector3d got = Centre(*s) - c0;
  EXPECT_NEAR((got - want).norm(), 0.0, 1e-9 * want.norm())
      << "moved " << got.transpose() << ", P A / m predicts " << want.transpose();
  // Pushing the face outward (positive) moves the solid along +x.
  EXPECT_GT(got.x(), 0);
}

TEST(SolidRuntimeTest, ScenePressuresAreLoadsWithIdsAndAreValidated) {
  auto s = Make(R"pb(
    mesh { block { nx: 2 ny: 2 nz: 2 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 1e4 density: 100 damping: 200 } }
    loads {
      point_forces { position { x: 1 y: 1 z: 1 } force { x: 1 } }
      pressures { region { box { min { x: -1 y: -1 z: -1 } max { x: 3 y: 3 z: 3 } } } pascals: 300 }
    }
  )pb");
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->load_ids(), (std::vector<int64_t>{1, 2})) << "point forces, then pressures";
  const double v0 = EnclosedVolume(*s);
  for (int i = 0; i < 200; ++i) ASSERT_OK(s->Step());
  EXPECT_GT(EnclosedVolume(*s), v0 * 1.001);
  ASSERT_OK(s->RemoveLoad(2));
  EXPECT_EQ(s->load_ids(), (std::vector<int64_t>{1}));
  EXPECT_THAT(scene::ParseScene(R"pb(
                mesh { block { nx: 1 ny: 1 nz: 1 } }
                loads { pressures { region { sphere { radius: 0 } } pascals: 1 } }
              )pb", "t"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("loads.pressures[0].region.sphere.radius must be > 0 metres")));
  EXPECT_THAT(scene::ParseScene(R"pb(
                mesh { block { nx: 1 ny: 1 nz: 1 } }
                loads { pressures { region { control_cells: 0 } } }
              )pb", "t"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("loads.pressures[0].pascals must be non-zero")));
}

TEST(SolidRuntimeTest, FixHoldsPointsWhereTheyAreAndUnfixReleasesThem) {
  auto s = Make(kBeam);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->constraint_ids().size(), 1u) << "the scene's clamp has an id";
  for (int i = 0; i < 100; ++i) ASSERT_OK(s->Step());
  const Points before = s->control_positions();
  const int32_t fixed_before = s->build_report().fixed_control_points;
  auto id = s->FixRegion(Parse<Region>("box { min { x: 0.9 y: -1 z: -1 } max { x: 1.1 y: 1 z: 1 } }"));
  ASSERT_OK(id);
  EXPECT_GT(s->build_report().fixed_control_points, fixed_before);
  std::vector<int64_t> held;
  for (int64_t i = 0; i < before.rows(); ++i) {
    if (before(i, 0) > 0.85) held.push_back(i);
  }
  ASSERT_FALSE(held.empty());
  for (int i = 0; i < 200; ++i) ASSERT_OK(s->Step());
  for (int64_t i : held) {
    EXPECT_EQ(s->control_positions().row(i), before.row(i)) << "control point " << i << " is held";
  }
  // The rest moved (the beam still sags between the two supports).
  EXPECT_NE(s->control_positions(), before);
  ASSERT_OK(s->Unfix(*id));
  EXPECT_EQ(s->build_report().fixed_control_points, fixed_before);
  for (int i = 0; i < 50; ++i) ASSERT_OK(s->Step());
  for (int64_t i : held) {
    EXPECT_NE(s->control_positions().row(i), before.row(i)) << "control point " << i << " is free";
  }
  EXPECT_EQ(s->rollbacks(), 0) << "fixing and unfixing never fire the energy guard";
  EXPECT_THAT(s->Unfix(*id), StatusIs(absl::StatusCode::kNotFound,
                                      HasSubstr(absl::StrCat("constraint id ", *id, " not found"))));
}

TEST(SolidRuntimeTest, UnfixingTheScenesClampFreesTheSolid) {
  std::string text(kBeam);
  text.replace(text.find(" damping: 3000"), 14, "");
  auto s = Make(text);
  ASSERT_NE(s, nullptr);
  for (int i = 0; i < 50; ++i) ASSERT_OK(s->Step());
  ASSERT_EQ(s->constraint_ids().size(), 1u);
  ASSERT_OK(s->Unfix(s->constraint_ids()[0]));
  EXPECT_EQ(s->build_report().fixed_control_points, 0);
  EXPECT_TRUE(s->constraint_ids().empty());
  // Free under gravity (no damping): the centre of mass falls at g, its
  // second difference per step g h^2 (central differences are exact for a
  // constant acceleration, with or without sub-steps).
  const double h = s->time_step();
  Eigen::Vector3d c0 = Centre(*s), c1;
  ASSERT_OK(s->Step());
  c1 = Centre(*s);
  for (int i = 0; i < 60; ++i) {
    ASSERT_OK(s->Step());
    const Eigen::Vector3d c2 = Centre(*s);
    EXPECT_NEAR((c2 - 2 * c1 + c0).z(), -9.81 * h * h, 1e-12) << "step " << i;
    c0 = c1;
    c1 = c2;
  }
  EXPECT_EQ(s->rollbacks(), 0);
}

// Every invalid call: rejected with its message, and nothing changes.
TEST(SolidRuntimeTest, InvalidCallsAreRejectedAndChangeNothing) {
  std::unique_ptr<Solid> s, twin;
  ASSERT_NO_FATAL_FAILURE(MakeTwins(kBeam, &s, &twin));
  for (int i = 0; i < 10; ++i) {
    ASSERT_OK(s->Step());
    ASSERT_OK(twin->Step());
  }
  const std::string state = s->SaveState();
  ASSERT_EQ(state, twin->SaveState());
  using Code = absl::StatusCode;
  const Code kInvalid = Code::kInvalidArgument;
  std::vector<std::tuple<std::string, absl::Status, Code, std::string>> cases;
  auto add = [&](std::string what, absl::Status st, Code code, std::string message) {
    cases.emplace_back(std::move(what), std::move(st), code, std::move(message));
  };
  add("nan force", s->AddPointForce(Parse<PointForce>("position { x: 0.5 } force { x: nan }")).status(),
      kInvalid, "point_force.force.x must be finite, got nan");
  add("outside", s->AddPointForce(Parse<PointForce>("position { x: 5 } force { x: 1 }")).status(),
      kInvalid, "point_force.position: point (5, 0, 0) is not inside the solid at rest");
  add("radius", s->AddPressure(Parse<Pressure>("region { sphere { radius: -1 } } pascals: 5")).status(),
      kInvalid, "pressure.region.sphere.radius must be > 0 metres, got -1");
  add("zero pressure", s->AddPressure(Parse<Pressure>("region { sphere { radius: 1 } }")).status(),
      kInvalid, "pressure.pascals must be non-zero");
  add("empty pressure region", s->AddPressure(Parse<Pressure>("pascals: 3")).status(), kInvalid,
      "pressure.region is empty: set a box, a sphere, control_cells or control_points");
  add("no face", s->AddPressure(Parse<Pressure>(
          "region { sphere { center { x: 0.5 } radius: 0.01 } } pascals: 3")).status(),
      kInvalid, "pressure.region selects no boundary face");
  add("cell range", s->AddPressure(Parse<Pressure>("region { control_cells: 6 } pascals: 3")).status(),
      kInvalid, "pressure.region.control_cells[0] (6) must be less than the number of control cells (6)");
  add("gravity", s->SetGravity(Parse<Vec3>("y: inf")), kInvalid, "gravity.y must be finite, got inf");
  add("remove", s->RemoveLoad(99), Code::kNotFound, "load id 99 not found");
  add("box", s->FixRegion(Parse<Region>("box { min { x: 1 } max { x: 0 } }")).status(), kInvalid,
      "region.box.min.x (1) must be <= box.max.x (0)");
  add("fix nothing", s->FixRegion(Parse<Region>("sphere { center { x: 0.5 } radius: 0.001 }")).status(),
      kInvalid, "region selects no control point");
  add("empty fix", s->FixRegion(Region()).status(), kInvalid, "region is empty");
  add("negative cell", s->FixRegion(Parse<Region>("control_cells: -2")).status(), kInvalid,
      "region.control_cells[0] must be a cell index >= 0, got -2");
  add("unfix", s->Unfix(42), Code::kNotFound, "constraint id 42 not found");
  add("poisson", s->PaintMaterial(Parse<MaterialPaint>(
          "region { sphere { radius: 1 } } material { poisson_ratio: 0.5 } strength: 1")),
      kInvalid, "paint.material.poisson_ratio must be in [0, 0.5)");
  add("no field", s->PaintMaterial(Parse<MaterialPaint>("region { sphere { radius: 1 } } strength: 1")),
      kInvalid, "paint.material sets no field");
  add("strength", s->PaintMaterial(Parse<MaterialPaint>(
          "region { sphere { radius: 1 } } material { density: 5 } strength: 1.5")),
      kInvalid, "paint.strength must be in (0, 1], got 1.5");
  add("no sample", s->PaintMaterial(Parse<MaterialPaint>(
          "region { sphere { center { x: 9 } radius: 1 } } material { density: 5 } strength: 1")),
      kInvalid, "paint.region contains no material sample");
  add("too stiff", s->PaintMaterial(Parse<MaterialPaint>(
          "region { box { min { x: -1 y: -1 z: -1 } max { x: 2 y: 1 z: 1 } } } "
          "material { young_modulus: 1e15 } strength: 1")),
      kInvalid, "explicit sub-steps");
  add("restore garbage", s->RestoreState("hello"), kInvalid, "not a dynsolid solid state");
  for (const auto& [what, status, code, message] : cases) {
    EXPECT_THAT(status, StatusIs(code, HasSubstr(message))) << what;
    EXPECT_EQ(s->SaveState(), state) << what << ": the state is unchanged";
  }
  for (int i = 0; i < 20; ++i) {
    ASSERT_OK(s->Step());
    ASSERT_OK(twin->Step());
  }
  EXPECT_EQ(s->control_positions(), twin->control_positions()) << "and so are later steps";
  EXPECT_EQ(s->SaveState(), twin->SaveState());
}

TEST(SolidRuntimeTest, BoundarySurfaceIsClosedWithTheRightEulerCharacteristic) {
  for (const auto& [text, euler] :
       {std::pair<std::string, int>{kFreeBlock, 2},
        std::pair<std::string, int>{R"pb(
          mesh { torus { major_radius: 2 tube_half_width: 0.5 segments: 6 cross: 1 } }
          subdivision { levels: 1 }
          materials { base { young_modulus: 1e4 density: 100 } }
        )pb", 0}}) {
    auto s = Make(text);
    ASSERT_NE(s, nullptr);
    EXPECT_EQ(s->topology_version(), 0);
    const Solid::Surface& surf = s->BoundarySurface();
    ASSERT_FALSE(surf.quads.empty());
    // Each directed edge once, and its reverse once: closed and oriented.
    std::map<std::pair<int32_t, int32_t>, int> directed;
    for (const auto& q : surf.quads) {
      for (int k = 0; k < 4; ++k) ++directed[{q[k], q[(k + 1) % 4]}];
    }
    for (const auto& [e, n] : directed) {
      EXPECT_EQ(n, 1) << "edge " << e.first << "-" << e.second;
      EXPECT_EQ(directed.count({e.second, e.first}), 1u) << "edge " << e.first << "-" << e.second;
    }
    const int64_t v = static_cast<int64_t>(surf.nodes.size());
    const int64_t e = static_cast<int64_t>(directed.size()) / 2;
    const int64_t f = static_cast<int64_t>(surf.quads.size());
    EXPECT_EQ(v - e + f, euler);
    // Outward: the enclosed volume is positive and near the rest volume.
    EXPECT_GT(EnclosedVolume(*s), 0.9 * s->rest_volume());
    // Positions are the nodes' own rows of A p, bit for bit, after motion.
    ASSERT_OK(s->SetGravity(Parse<Vec3>("z: -3")));
    // And a pressure around the first quad, to deform it.
    const Points rest = s->SurfacePositions();
    Eigen::Vector3d at = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) at += 0.25 * rest.row(surf.quads[0][k]).transpose();
    ASSERT_OK(s->AddPressure(Parse<Pressure>(absl::StrCat(
        "region { sphere { center { x: ", at.x(), " y: ", at.y(), " z: ", at.z(),
        " } radius: 0.6 } } pascals: 2000"))));
    for (int i = 0; i < 20; ++i) ASSERT_OK(s->Step());
    const Points nodes = s->NodePositions();
    const Points x = s->SurfacePositions();
    ASSERT_EQ(x.rows(), v);
    for (int64_t i = 0; i < v; ++i) ASSERT_EQ(x.row(i), nodes.row(surf.nodes[i])) << "vertex " << i;
    const Solid::Bounds b = s->SurfaceBounds();
    EXPECT_EQ(b.min, x.colwise().minCoeff().transpose());
    EXPECT_EQ(b.max, x.colwise().maxCoeff().transpose());
    const Solid::SurfaceFields fields = s->ComputeSurfaceFields();
    ASSERT_EQ(fields.displacement.size(), static_cast<size_t>(v));
    ASSERT_EQ(fields.strain.size(), static_cast<size_t>(v));
    ASSERT_EQ(fields.stiffness.size(), static_cast<size_t>(v));
    double most = 0;
    for (int64_t i = 0; i < v; ++i) {
      EXPECT_TRUE(std::isfinite(fields.displacement[i]) && std::isfinite(fields.strain[i]));
      EXPECT_GE(fields.strain[i], 0.0f);
      EXPECT_FLOAT_EQ(fields.stiffness[i], 1e4f) << "uniform E";
      most = std::max(most, static_cast<double>(fields.displacement[i]));
    }
    EXPECT_GT(most, 0) << "it moved";
  }
}

}  // namespace
}  // namespace dynsolid::solid
