// Material painting of a live solid (stiffness, density, the fields a
// watcher sees), exact save/restore across paints, and paints, states and
// unfixes prepared on another thread while the solid steps.
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/solid/solid.h"
#include "tests/solid/solid_support.h"

namespace dynsolid::solid {
namespace {

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

// Two solids of kPaintBlock with `solver`, 5 steps in: what a change
// prepared off the loop (`live`) is checked against (`reference`).
void MakeSteppedPair(const char* solver, std::unique_ptr<Solid>* reference,
                     std::unique_ptr<Solid>* live) {
  ASSERT_NO_FATAL_FAILURE(MakeTwins(kPaintBlock + std::string(solver), reference, live));
  for (Solid* s : {reference->get(), live->get()}) {
    for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
  }
}

// Runs prepare() on a thread of its own while `live` takes `steps` steps
// (what the server does off its simulation loop); then `reference` takes
// as many. `*prepared` holds what prepare() returned.
template <typename T, typename Prepare>
void PrepareWhileStepping(Solid& live, Solid& reference, int steps, Prepare prepare,
                          absl::StatusOr<T>* prepared) {
  std::thread builder([&] { *prepared = prepare(); });
  for (int i = 0; i < steps; ++i) ASSERT_OK(live.Step());
  builder.join();
  ASSERT_OK(*prepared);
  for (int i = 0; i < steps; ++i) ASSERT_OK(reference.Step());
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
  const MaterialPaint stiffer = Parse<MaterialPaint>(kStifferBall);
  const MaterialPaint softer = Parse<MaterialPaint>(
      "region { sphere { center { x: 1 y: 1.5 z: 1.5 } radius: 0.9 } } "
      "material { young_modulus: 5e4 } strength: 1");
  for (const char* solver : kPaintSolvers) {
    std::unique_ptr<Solid> reference, live;
    ASSERT_NO_FATAL_FAILURE(MakeSteppedPair(solver, &reference, &live));
    // Prepared on a thread while `live` takes 15 steps.
    absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> prepared;
    ASSERT_NO_FATAL_FAILURE(PrepareWhileStepping(
        *live, *reference, 15, [&] { return live->PreparePaint(stiffer); }, &prepared));
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
    ASSERT_NO_FATAL_FAILURE(PrepareWhileStepping(
        *live, *reference, 5, [&] { return live->PreparePaint(much_stiffer); }, &hard));
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
  const MaterialPaint paint = Parse<MaterialPaint>(kStifferBall);
  for (const char* solver : kPaintSolvers) {
    std::unique_ptr<Solid> reference, live;
    ASSERT_NO_FATAL_FAILURE(MakeSteppedPair(solver, &reference, &live));
    const std::string before = live->SaveState();
    for (Solid* s : {reference.get(), live.get()}) {
      ASSERT_OK(s->PaintMaterial(paint));
      for (int i = 0; i < 5; ++i) ASSERT_OK(s->Step());
    }
    absl::StatusOr<std::shared_ptr<Solid::PreparedState>> prepared;
    ASSERT_NO_FATAL_FAILURE(PrepareWhileStepping(
        *live, *reference, 10, [&] { return live->PrepareState(before); }, &prepared));
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
    std::unique_ptr<Solid> reference, live;
    ASSERT_NO_FATAL_FAILURE(MakeSteppedPair(solver, &reference, &live));
    ASSERT_EQ(live->constraint_ids().size(), 1u);
    const int64_t clamp = live->constraint_ids()[0];
    // The scene's clamp: the stable step was estimated with it, so it is
    // estimated again.
    absl::StatusOr<std::shared_ptr<Solid::PreparedUnfix>> prepared;
    ASSERT_NO_FATAL_FAILURE(PrepareWhileStepping(
        *live, *reference, 10, [&] { return live->PrepareUnfix(clamp); }, &prepared));
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
