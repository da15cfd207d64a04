// Runtime edits of a live solid (loads, constraints, material painting),
// exact save/restore, and the boundary surface for watchers.
#include <cmath>
#include <cstring>
#include <cstdlib>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <tuple>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::solid {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

std::unique_ptr<Solid> Make(const std::string& text) { return testing::MakeSolid(text); }

using ::dynsolid::testing::Parse;

// A block at one level under a load, and the two ways the paint and
// restore tests step it (local frame + central difference, corotational +
// backward Euler).
constexpr char kPaintBlock[] = R"pb(
    mesh { block { nx: 3 ny: 3 nz: 3 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 1e5 density: 1000 damping: 200 } }
    constraints { fixed { box { min { x: -1 y: -1 z: -0.01 } max { x: 4 y: 4 z: 0.01 } } } }
    loads { point_forces { position { x: 1.5 y: 1.5 z: 3 } force { x: 3000 } } }
  )pb";
constexpr const char* kPaintSolvers[] = {
    "solver { time_step: 1e-3 }",
    "solver { model: COROTATIONAL integrator: BACKWARD_EULER time_step: 2e-3 }"};

// A ball of stiffer, denser material painted at 70 % over the block's top.
constexpr char kStifferBall[] =
    "region { sphere { center { x: 1.5 y: 1.5 z: 2 } radius: 0.8 } } "
    "material { young_modulus: 4e5 density: 1500 } strength: 0.7";

// Centre of mass from the row sums of Mt.
Eigen::Vector3d Centre(const Solid& s) {
  const Points& p = s.control_positions();
  const Points w = s.ApplyMass(Points::Ones(p.rows(), 3));
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int64_t i = 0; i < p.rows(); ++i) c += w(i, 0) * p.row(i).transpose();
  return c / s.total_mass();
}

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

const char* kFreeBlock = R"pb(
  mesh { block { nx: 2 ny: 2 nz: 2 } }
  subdivision { levels: 1 }
  materials { base { young_modulus: 1e4 density: 100 } }
  solver { time_step: 1e-3 cg_tolerance: 1e-13 }
)pb";

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
  auto a = Make(kFreeBlock);
  auto b = Make(kFreeBlock);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
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

const char* kBeam = R"pb(
  mesh { beam { length: 1 width: 0.1 height: 0.1 cells_along: 6 cells_across: 1 } }
  subdivision { levels: 1 }
  sharp { crease_angle_degrees: 60 }
  materials { base { young_modulus: 1e6 density: 1000 damping: 3000 } }
  constraints { fixed { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 1 z: 1 } } } }
  loads { gravity { z: -9.81 } }
  traced { name: "tip" position { x: 1 y: 0 z: 0 } }
  solver { time_step: 1e-3 }
)pb";

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

TEST(SolidRuntimeTest, PaintingStiffnessOnHalfTheBeamChangesTheStaticDeflection) {
  std::string text(kBeam);
  text.replace(text.find("solver {"), 8, "solver { model: COROTATIONAL ");
  auto s = Make(text);
  ASSERT_NE(s, nullptr);
  auto tip = [&]() {
    auto p = s->SolveStaticLinear();
    EXPECT_OK(p);
    return p.ok() ? s->TracedPositionsAt(*p)[0].z() : 0.0;
  };
  const double base = tip();
  ASSERT_LT(base, 0);
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(
      "region { box { min { x: -1 y: -1 z: -1 } max { x: 0.5 y: 1 z: 1 } } } "
      "material { young_modulus: 1e7 } strength: 1")));
  const double stiffer = tip();
  EXPECT_LT(std::abs(stiffer), 0.8 * std::abs(base)) << "a stiffer root half sags less";
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(
      "region { box { min { x: 0.5 y: -1 z: -1 } max { x: 2 y: 1 z: 1 } } } "
      "material { young_modulus: 2e5 } strength: 1")));
  const double softer = tip();
  EXPECT_GT(std::abs(softer), std::abs(stiffer)) << "a softer tip half sags more";
  EXPECT_GT(s->build_report().linear_groups + s->build_report().cubic_groups, 0);
  for (int i = 0; i < 50; ++i) ASSERT_OK(s->Step());
  EXPECT_EQ(s->rollbacks(), 0);
}

// A paint takes over what it does not change (element matrices of untouched
// groups, the measure, Mt and Dt when no density or damping changed). The
// result must be the bits a from-scratch rebuild gives, for both models,
// for a stiffness-only paint and one that changes density too, and for a
// state restored across a paint.
TEST(SolidRuntimeTest, PaintReusesUnchangedPartsWithTheBitsOfAFullRebuild) {
  const std::string base = kPaintBlock;
  const char* paints[] = {
      "region { sphere { center { x: 1.5 y: 1.5 z: 2 } radius: 0.8 } } "
      "material { young_modulus: 4e5 } strength: 1",
      "region { sphere { center { x: 1 y: 1.5 z: 1.5 } radius: 0.9 } } "
      "material { young_modulus: 2e5 density: 3000 } strength: 0.5"};
  for (const char* solver : kPaintSolvers) {
    for (const char* paint : paints) {
      std::vector<Points> finals;
      std::string saved;
      for (bool reuse : {true, false}) {
        auto s = Make(base + solver);
        ASSERT_NE(s, nullptr);
        s->SetPaintReuseForTesting(reuse);
        for (int i = 0; i < 10; ++i) ASSERT_OK(s->Step());
        if (reuse) saved = s->SaveState();
        ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(paint)));
        for (int i = 0; i < 20; ++i) ASSERT_OK(s->Step());
        finals.push_back(s->control_positions());
      }
      EXPECT_TRUE(finals[0] == finals[1]) << solver << " | " << paint;
      // Restore the pre-paint state into a painted solid (a rebuild of the
      // material the other way), paint again: the same bits once more.
      auto s = Make(base + solver);
      ASSERT_NE(s, nullptr);
      ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(paint)));
      ASSERT_OK(s->RestoreState(saved));
      ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(paint)));
      for (int i = 0; i < 20; ++i) ASSERT_OK(s->Step());
      EXPECT_TRUE(s->control_positions() == finals[1]) << "restored: " << solver << " | " << paint;
    }
  }
}

// Undo after a paint and redo after that undo take back the material the
// solid had just before (Impl::RetiredMaterial) instead of building it, and
// the points of the loads the solid has (a force, a drag, a curve) instead
// of locating them again: the same bits as restoring either state into a
// solid that builds and locates everything, and the same bits after more
// steps.
TEST(SolidRuntimeTest, UndoAndRedoOfAPaintTakeBackTheMaterialWithTheBitsOfABuild) {
  const std::string base = kPaintBlock;
  const MaterialPaint paint = Parse<MaterialPaint>(kStifferBall);
  for (const char* solver : kPaintSolvers) {
    auto live = Make(base + solver);
    ASSERT_NE(live, nullptr);
    for (int i = 0; i < 10; ++i) ASSERT_OK(live->Step());
    ASSERT_OK(live->AddPointForce(Parse<PointForce>(
        "position { x: 2.2 y: 1.1 z: 2.9 } force { x: 300 y: 0 z: -200 }")));
    ASSERT_OK(live->AddDrag(Parse<Drag>(
        "material_point { x: 0.7 y: 2.1 z: 2.5 } target { x: 0.6 y: 2.1 z: 2.8 } stiffness: 4000")));
    ASSERT_OK(live->AddCurveDrag(Parse<CurveDrag>(
        "material_points { x: 0.5 y: 0.5 z: 2.5 } material_points { x: 2.5 y: 0.5 z: 2.5 } "
        "targets { x: 0.5 y: 0.4 z: 2.7 } targets { x: 2.5 y: 0.4 z: 2.7 } stiffness: 2000 "
        "samples: 5")));
    for (int i = 0; i < 5; ++i) ASSERT_OK(live->Step());
    const std::string before = live->SaveState();
    ASSERT_OK(live->PaintMaterial(paint));
    for (int i = 0; i < 10; ++i) ASSERT_OK(live->Step());
    const std::string after = live->SaveState();
    for (const std::string* state : {&before, &after, &before}) {
      const int64_t taken = live->build_report().materials_taken_back;
      ASSERT_OK(live->RestoreState(*state));
      EXPECT_EQ(live->build_report().materials_taken_back, taken + 1) << solver;
      auto fresh = Make(base + solver);
      ASSERT_NE(fresh, nullptr);
      ASSERT_OK(fresh->RestoreState(*state));
      EXPECT_EQ(fresh->build_report().materials_taken_back, 0) << solver;
      for (int i = 0; i < 20; ++i) {
        ASSERT_OK(live->Step());
        ASSERT_OK(fresh->Step());
      }
      EXPECT_TRUE(live->control_positions() == fresh->control_positions()) << solver;
      EXPECT_EQ(live->SaveState(), fresh->SaveState()) << solver;
    }
  }
}

// A paint prepared on another thread while the solid steps (what the server
// does off its simulation loop), installed 15 steps later, gives the bits of
// painting at that step; one prepared before another paint is prepared
// again for the new material; a failing one changes nothing.
TEST(SolidRuntimeTest, PaintPreparedWhileSteppingGivesTheBitsOfPaintingWhenApplied) {
  const std::string base = kPaintBlock;
  const MaterialPaint stiffer = Parse<MaterialPaint>(kStifferBall);
  const MaterialPaint softer = Parse<MaterialPaint>(
      "region { sphere { center { x: 1 y: 1.5 z: 1.5 } radius: 0.9 } } "
      "material { young_modulus: 5e4 } strength: 1");
  for (const char* solver : kPaintSolvers) {
    auto reference = Make(base + solver);
    auto live = Make(base + solver);
    ASSERT_NE(reference, nullptr);
    ASSERT_NE(live, nullptr);
    for (int i = 0; i < 5; ++i) {
      ASSERT_OK(reference->Step());
      ASSERT_OK(live->Step());
    }
    // Prepared on a thread while `live` takes 15 steps.
    absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> prepared;
    std::thread builder([&] { prepared = live->PreparePaint(stiffer); });
    for (int i = 0; i < 15; ++i) ASSERT_OK(live->Step());
    builder.join();
    ASSERT_OK(prepared);
    for (int i = 0; i < 15; ++i) ASSERT_OK(reference->Step());
    ASSERT_OK(reference->PaintMaterial(stiffer));
    ASSERT_OK(live->ApplyPaint(**prepared));
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    // Prepared, then another paint lands first: applying it paints the
    // current material.
    absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> stale = live->PreparePaint(stiffer);
    ASSERT_OK(stale);
    ASSERT_OK(live->PaintMaterial(softer));
    ASSERT_OK(live->ApplyPaint(**stale));
    ASSERT_OK(reference->PaintMaterial(softer));
    ASSERT_OK(reference->PaintMaterial(stiffer));
    for (int i = 0; i < 20; ++i) {
      ASSERT_OK(live->Step());
      ASSERT_OK(reference->Step());
    }
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    // Much stiffer: the explicit step needs more sub-steps, so the stable
    // step is estimated anew (on the prepared model's own thread pool).
    const MaterialPaint much_stiffer = Parse<MaterialPaint>(
        "region { sphere { center { x: 1.5 y: 1.5 z: 2.5 } radius: 0.6 } } "
        "material { young_modulus: 1e9 } strength: 1");
    const int before_substeps = live->build_report().substeps;
    absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> hard;
    std::thread hard_builder([&] { hard = live->PreparePaint(much_stiffer); });
    for (int i = 0; i < 5; ++i) ASSERT_OK(live->Step());
    hard_builder.join();
    ASSERT_OK(hard);
    for (int i = 0; i < 5; ++i) ASSERT_OK(reference->Step());
    ASSERT_OK(live->ApplyPaint(**hard));
    ASSERT_OK(reference->PaintMaterial(much_stiffer));
    if (std::string(solver).find("BACKWARD") == std::string::npos) {
      EXPECT_GT(live->build_report().substeps, before_substeps)
          << "the estimate was not needed: stable step " << live->build_report().stable_step;
    }
    for (int i = 0; i < 10; ++i) {
      ASSERT_OK(live->Step());
      ASSERT_OK(reference->Step());
    }
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver << " (much stiffer)";
    // A paint of no sample is refused when prepared.
    EXPECT_THAT(live->PreparePaint(Parse<MaterialPaint>(
                    "region { sphere { center { x: 9 y: 9 z: 9 } radius: 0.1 } } "
                    "material { young_modulus: 1e6 } strength: 1")),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("no material sample")));
  }
}

// A state prepared on another thread while the solid steps (a server's undo
// off its loop), restored later, gives the bits of restoring it then: across
// a paint (the material rebuilt), and after another paint landed in between
// (prepared again from its bytes).
TEST(SolidRuntimeTest, StatePreparedWhileSteppingRestoresTheBitsOfRestoringThen) {
  const std::string base = kPaintBlock;
  const MaterialPaint paint = Parse<MaterialPaint>(kStifferBall);
  for (const char* solver : kPaintSolvers) {
    auto reference = Make(base + solver);
    auto live = Make(base + solver);
    ASSERT_NE(reference, nullptr);
    ASSERT_NE(live, nullptr);
    for (Solid* s : {reference.get(), live.get()}) {
      for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
    }
    const std::string before = live->SaveState();
    for (Solid* s : {reference.get(), live.get()}) {
      ASSERT_OK(s->PaintMaterial(paint));
      for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
    }
    absl::StatusOr<std::shared_ptr<Solid::PreparedState>> prepared;
    std::thread builder([&] { prepared = live->PrepareState(before); });
    for (int i = 0; i < 10; ++i) ASSERT_OK(live->Step());
    builder.join();
    ASSERT_OK(prepared);
    for (int i = 0; i < 10; ++i) ASSERT_OK(reference->Step());
    ASSERT_OK(reference->RestoreStateAtClock(before, reference->time(), reference->steps()));
    ASSERT_OK(live->RestorePreparedAtClock(**prepared, live->time(), live->steps()));
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    // Prepared, then a paint lands first: restored from its bytes again.
    absl::StatusOr<std::shared_ptr<Solid::PreparedState>> stale = live->PrepareState(before);
    ASSERT_OK(stale);
    for (Solid* s : {reference.get(), live.get()}) ASSERT_OK(s->PaintMaterial(paint));
    ASSERT_OK(live->RestorePreparedAtClock(**stale, live->time(), live->steps()));
    ASSERT_OK(reference->RestoreStateAtClock(before, reference->time(), reference->steps()));
    for (Solid* s : {reference.get(), live.get()}) {
      for (int i = 0; i < 20; ++i) ASSERT_OK(s->Step());
    }
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    // Bad bytes are refused when prepared.
    EXPECT_THAT(live->PrepareState(before.substr(0, 100)),
                StatusIs(absl::StatusCode::kDataLoss, HasSubstr("checksum")));
  }
}

// An unfix prepared on another thread while the solid steps (its stable-step
// estimate on a model of its own), applied later, gives the bits of
// unfixing then; one prepared before another change is prepared again.
TEST(SolidRuntimeTest, UnfixPreparedWhileSteppingGivesTheBitsOfUnfixingWhenApplied) {
  for (const char* solver : kPaintSolvers) {
    auto reference = Make(kPaintBlock + std::string(solver));
    auto live = Make(kPaintBlock + std::string(solver));
    ASSERT_NE(reference, nullptr);
    ASSERT_NE(live, nullptr);
    for (Solid* s : {reference.get(), live.get()}) {
      for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
    }
    ASSERT_EQ(live->constraint_ids().size(), 1u);
    const int64_t clamp = live->constraint_ids()[0];
    // The scene's clamp: the stable step was estimated with it, so it is
    // estimated again.
    absl::StatusOr<std::shared_ptr<Solid::PreparedUnfix>> prepared;
    std::thread builder([&] { prepared = live->PrepareUnfix(clamp); });
    for (int i = 0; i < 10; ++i) ASSERT_OK(live->Step());
    builder.join();
    ASSERT_OK(prepared);
    for (int i = 0; i < 10; ++i) ASSERT_OK(reference->Step());
    ASSERT_OK(reference->Unfix(clamp));
    ASSERT_OK(live->ApplyUnfix(**prepared));
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    // Prepared, then a fix lands first: prepared again for the new set.
    const Region top =
        Parse<Region>("box { min { x: -1 y: -1 z: 2.99 } max { x: 4 y: 4 z: 3.01 } }");
    const Region side =
        Parse<Region>("box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 4 z: 4 } }");
    absl::StatusOr<int64_t> a = live->FixRegion(top);
    absl::StatusOr<int64_t> b = reference->FixRegion(top);
    ASSERT_OK(a);
    ASSERT_OK(b);
    absl::StatusOr<std::shared_ptr<Solid::PreparedUnfix>> stale = live->PrepareUnfix(*a);
    ASSERT_OK(stale);
    ASSERT_OK(live->FixRegion(side).status());
    ASSERT_OK(reference->FixRegion(side).status());
    ASSERT_OK(live->ApplyUnfix(**stale));
    ASSERT_OK(reference->Unfix(*b));
    for (Solid* s : {reference.get(), live.get()}) {
      for (int i = 0; i < 20; ++i) ASSERT_OK(s->Step());
    }
    EXPECT_EQ(live->SaveState(), reference->SaveState()) << solver;
    EXPECT_THAT(live->PrepareUnfix(12345),
                StatusIs(absl::StatusCode::kNotFound, HasSubstr("constraint id 12345")));
  }
}

TEST(SolidRuntimeTest, PaintingDensityChangesTheMassExactly) {
  // Level 0: two unit hexahedra, exact volumes.
  const char* text = R"pb(
    mesh { block { nx: 2 ny: 1 nz: 1 } }
    subdivision { levels: 0 }
    materials { base { density: 1000 } }
  )pb";
  auto s = Make(text);
  ASSERT_NE(s, nullptr);
  EXPECT_NEAR(s->total_mass(), 2000, 1e-9);
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>("region { control_cells: 0 } material { density: 3000 } strength: 1")));
  EXPECT_NEAR(s->total_mass(), 3000 + 1000, 1e-9);
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>("region { control_cells: 1 } material { density: 3000 } strength: 0.25")));
  EXPECT_NEAR(s->total_mass(), 3000 + 1500, 1e-9) << "a quarter of the way: 1000 + 0.25 * 2000";
  // A box far larger than the solid: every sample is deeper than the
  // falloff band, so the weight is the strength everywhere.
  auto b = Make(kFreeBlock);
  ASSERT_NE(b, nullptr);
  ASSERT_OK(b->PaintMaterial(Parse<MaterialPaint>(
      "region { box { min { x: -10 y: -10 z: -10 } max { x: 12 y: 12 z: 12 } } } "
      "material { density: 250 } strength: 1")));
  EXPECT_NEAR(b->total_mass(), 250 * b->rest_volume(), 1e-9 * b->total_mass());
  // Gravity follows the painted density: a free fall still at g.
  ASSERT_OK(b->SetGravity(Parse<Vec3>("z: -10")));
  const Eigen::Vector3d c0 = Centre(*b);
  for (int i = 0; i < 10; ++i) ASSERT_OK(b->Step());
  EXPECT_NEAR(Centre(*b).z() - c0.z(), -10 * 1e-6 * 55, 1e-9);
}

// Every invalid call: rejected with its message, and nothing changes.
TEST(SolidRuntimeTest, InvalidCallsAreRejectedAndChangeNothing) {
  auto s = Make(kBeam);
  auto twin = Make(kBeam);
  ASSERT_NE(s, nullptr);
  ASSERT_NE(twin, nullptr);
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

// SaveStateParts joins to SaveState's bytes; states saved while the
// material is unchanged share one material section (what the undo history
// keeps once), a paint makes a new one, and a joined state restores.
TEST(SolidRuntimeTest, StatePartsShareTheMaterialSectionUntilTheMaterialChanges) {
  auto s = Make(std::string(kPaintBlock) + kPaintSolvers[0]);
  ASSERT_NE(s, nullptr);
  const SavedState first = s->SaveStateParts();
  EXPECT_EQ(Solid::JoinState(first), s->SaveState());
  ASSERT_OK(s->Step());
  const SavedState second = s->SaveStateParts();
  ASSERT_NE(first.section, nullptr);
  EXPECT_EQ(first.section.get(), second.section.get());
  EXPECT_NE(first.head, second.head);
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(
      "region { sphere { center { x: 1.5 y: 1.5 z: 2 } radius: 0.8 } } "
      "material { young_modulus: 4e5 } strength: 1")));
  const SavedState painted = s->SaveStateParts();
  EXPECT_NE(painted.section.get(), second.section.get());
  EXPECT_NE(*painted.section, *second.section);
  EXPECT_EQ(Solid::JoinState(painted), s->SaveState());
  ASSERT_OK(s->RestoreState(Solid::JoinState(second)));
  EXPECT_EQ(s->SaveState(), Solid::JoinState(second));
  // A whole state in the head alone joins to itself.
  SavedState whole;
  whole.head = s->SaveState();
  EXPECT_EQ(Solid::JoinState(whole), s->SaveState());
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

TEST(SolidRuntimeTest, StiffnessFieldShowsPaintedModulus) {
  auto s = Make(kFreeBlock);
  ASSERT_NE(s, nullptr);
  const Solid::SurfaceFields rest = s->ComputeSurfaceFields();
  for (float x : rest.displacement) EXPECT_EQ(x, 0.0f);
  for (float x : rest.strain) EXPECT_EQ(x, 0.0f);
  ASSERT_OK(s->PaintMaterial(Parse<MaterialPaint>(
      "region { box { min { x: -0.6 y: -5 z: -5 } max { x: 1 y: 5 z: 5 } } } "
      "material { young_modulus: 5e4 } strength: 1")));
  const Solid::SurfaceFields painted = s->ComputeSurfaceFields();
  const Points x = s->SurfacePositions();
  for (size_t i = 0; i < painted.stiffness.size(); ++i) {
    if (x(i, 0) < 0.3) {
      EXPECT_NEAR(painted.stiffness[i], 5e4, 1) << "painted side";
    }
    if (x(i, 0) > 1.7) {
      EXPECT_NEAR(painted.stiffness[i], 1e4, 1e-2) << "unpainted side";
    }
  }
}

TEST(SolidRuntimeTest, MassFieldShowsPaintedDensityInsideASphereOnly) {
  auto s = Make(kFreeBlock);  // 2 m cube at density 100, cells of 0.5 m at level 1
  ASSERT_NE(s, nullptr);
  const Solid::SurfaceFields rest = s->ComputeSurfaceFields();
  const size_t nv = s->BoundarySurface().nodes.size();
  ASSERT_EQ(rest.mass.size(), nv);
  for (float m : rest.mass) EXPECT_FLOAT_EQ(m, 100.0f) << "uniform density";
  const double mass_before = s->total_mass();
  // A hard-edged sphere of density 900 around the corner (0, 0, 0).
  const Eigen::Vector3d centre(0, 0, 0);
  const double radius = 0.9;
  ASSERT_OK(s->PaintMaterial(
      Parse<MaterialPaint>("region { sphere { center { x: 0 y: 0 z: 0 } radius: 0.9 } } "
                           "material { density: 900 } strength: 1 falloff: 0.05")));
  const Solid::SurfaceFields painted = s->ComputeSurfaceFields();
  ASSERT_EQ(painted.mass.size(), nv);
  const Points x = s->SurfacePositions();
  // A vertex's cells reach at most one cell diagonal (0.5 sqrt 3 m) from it.
  const double reach = 0.5 * std::sqrt(3.0);
  int far = 0;
  size_t nearest = 0;
  for (size_t i = 0; i < nv; ++i) {
    const double r = (x.row(i).transpose() - centre).norm();
    if (r < (x.row(nearest).transpose() - centre).norm()) nearest = i;
    EXPECT_GE(painted.mass[i], 100.0f - 1e-3f) << "vertex " << i;
    EXPECT_LE(painted.mass[i], 900.0f + 1e-3f) << "vertex " << i;
    if (r > radius + reach) {
      EXPECT_FLOAT_EQ(painted.mass[i], 100.0f) << "vertex " << i << " at " << r << " m";
      ++far;
    }
    // Only the density was painted.
    EXPECT_FLOAT_EQ(painted.stiffness[i], 1e4f) << "vertex " << i;
  }
  // The corner vertex: its one boundary cell lies almost all in the sphere.
  EXPECT_GT(painted.mass[nearest], 600.0f) << "vertex " << nearest << " at " << x.row(nearest);
  EXPECT_GT(far, static_cast<int>(nv) / 2);
  EXPECT_GT(s->total_mass(), mass_before);
}

}  // namespace
}  // namespace dynsolid::solid
