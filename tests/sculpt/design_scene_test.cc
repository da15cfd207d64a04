// The "save as" of a design (sculpt/design_scene.h, scene.proto Design): a
// clay bar painted, bent until it flows, baked, bent again and pinned is
// written as a scene file's text; the solid created from that text has
// the same rest control points, sharp tags, material samples, clay state
// and pins, bit for bit, and from the same positions it moves the same.
// A design that does not fit its scene is refused naming the field.
#include <cstdio>
#include <memory>
#include <string>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/sculpt/apply.h"
#include "solver/sculpt/design_scene.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::sculpt {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

absl::StatusOr<std::unique_ptr<solid::Solid>> Build(const Scene& scene) {
  ASSIGN_OR_RETURN(scene::Discretization d, scene::BuildDiscretization(scene, "", std::nullopt));
  return solid::Solid::Create(scene, std::move(d), 2);
}

Region Ball(double x, double y, double z, double r) {
  Region out;
  out.mutable_sphere()->mutable_center()->set_x(x);
  out.mutable_sphere()->mutable_center()->set_y(y);
  out.mutable_sphere()->mutable_center()->set_z(z);
  out.mutable_sphere()->set_radius(r);
  return out;
}

// Bends the bar's free end down by `amount` x^2 and lets it flow.
void BendAndFlow(solid::Solid& s, double amount, int steps) {
  Points bent = s.control_positions();
  const Points rest = s.discretization().control().positions();
  bent.col(2) += amount * rest.col(0).array().square().matrix();
  s.SetAtRest(bent);
  for (int i = 0; i < steps; ++i) ASSERT_OK(s.Step());
}

class DesignSceneTest : public ::testing::TestWithParam<const char*> {
 protected:
  // The sculpted bar and the scene it stands on now.
  void SetUp() override {
    scene_ = *scene::ParseScene(absl::StrCat(R"pb(
      name: "clay bar"
      mesh { block { nx: 6 ny: 2 nz: 2 } }
      subdivision { levels: 1 }
      sharp { crease_angle_degrees: 60 }
      materials { base { young_modulus: 2e4 density: 100 damping: 2000 yield_strain: 0.002
                         flow_rate: 1000 } }
      constraints { fixed { box { min { x: -1 y: -1 z: -1 } max { x: 0.01 y: 5 z: 5 } } } }
      environment { floor { point { z: -3 } normal { z: 1 } } }
      solver { time_step: 1e-3 model: COROTATIONAL corotation: )pb", GetParam(), " }"),
                                "test");
    original_ = scene_;
    ASSERT_OK_AND_ASSIGN(solid_, Build(scene_));
    // A stiffer, yielding-later patch with a smooth edge: many samples of
    // their own.
    MaterialPaint paint;
    *paint.mutable_region() = Ball(4.5, 1, 1, 1.2);
    paint.mutable_material()->set_young_modulus(5e4);
    paint.mutable_material()->set_yield_strain(0.004);
    paint.set_strength(1);
    paint.set_falloff(0.5);
    ASSERT_OK(solid_->PaintMaterial(paint));
    BendAndFlow(*solid_, 0.02, 600);
    ASSERT_GT(solid_->plastic_stats().yielded, 0);
    // Bake the bend into the mesh, then bend it again: the rest shape is
    // the baked mesh plus new plastic offsets.
    TopologyEdit bake;
    const Points p = solid_->control_positions();
    for (Eigen::Index i = 0; i < p.rows(); ++i) {
      for (int k = 0; k < 3; ++k) bake.mutable_bake()->add_rest_positions(p(i, k));
    }
    ASSERT_OK_AND_ASSIGN(AppliedEdit baked, ApplyEdit(scene_, *solid_, bake));
    solid_ = std::move(baked.solid);
    scene_ = baked.scene;
    BendAndFlow(*solid_, -0.01, 300);
    // A second pin, over the free end's top.
    ASSERT_OK(solid_->FixRegion(Ball(6, 2, 2, 0.3)).status());
  }

  Scene original_, scene_;
  std::unique_ptr<solid::Solid> solid_;
};

TEST_P(DesignSceneTest, ASavedDesignIsCreatedAgainBitForBit) {
  const Scene design = DesignScene(scene_, *solid_);
  const std::string text = SceneText(design, "a test design\nsecond line");
  EXPECT_THAT(text, HasSubstr("# a test design\n# second line\n"));
  std::printf("%s: the scene file has %zu bytes, %d materials, %d sample runs, %d plastic "
              "offsets\n",
              GetParam(), text.size(), design.design().materials_size(),
              design.design().sample_runs_size() / 2, design.design().plastic_offsets_size());
  ASSERT_GT(design.design().materials_size(), 2) << "the paint's falloff makes many samples";
  ASSERT_OK_AND_ASSIGN(Scene read, scene::ParseScene(text, "saved"));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<solid::Solid> again, Build(read));

  // Rest shape (the bake's), sharp tags, topology.
  const scene::Discretization& a = solid_->discretization();
  const scene::Discretization& b = again->discretization();
  ASSERT_EQ(a.control().num_cells(), b.control().num_cells());
  EXPECT_TRUE(a.control().positions() == b.control().positions());
  EXPECT_EQ(a.control_sharp, b.control_sharp);
  EXPECT_GT(std::count(b.control_sharp.begin(), b.control_sharp.end(), 1), 0);
  EXPECT_FALSE(a.control().positions() == scene::BuildDiscretization(original_, "", std::nullopt)
                                              ->control()
                                              .positions())
      << "the scene before the bake has another rest shape";
  // Materials and clay, as the solid holds them (the same walk over both).
  const Design da = solid_->SaveDesign(), db = again->SaveDesign();
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(da, db));
  EXPECT_GT(da.plastic_offsets_size(), 0);
  EXPECT_EQ(solid_->plastic_stats().yielded, again->plastic_stats().yielded);
  EXPECT_EQ(solid_->plastic_stats().max_strain, again->plastic_stats().max_strain);
  EXPECT_EQ(solid_->total_mass(), again->total_mass());
  // Pins: the same control points.
  const auto ca = solid_->ActiveConstraints(), cb = again->ActiveConstraints();
  ASSERT_EQ(ca.size(), cb.size());
  for (size_t i = 0; i < ca.size(); ++i) EXPECT_EQ(ca[i].control_points, cb[i].control_points);
  // The floor came along.
  EXPECT_TRUE(read.environment().has_floor());

  // From the same positions at rest, both move alike: the rest state is
  // the same (the sub-steps may differ: a paint never lowers them, a new
  // solid picks its own), so the bits may not; the trajectories agree to
  // the integrator's accuracy. (The pin added last holds its points where
  // they were when it was added, the saved one where they are at rest: a
  // design is at rest. It is taken off both.)
  ASSERT_OK(solid_->Unfix(solid_->constraint_ids().back()));
  ASSERT_OK(again->Unfix(again->constraint_ids().back()));
  std::printf("%s: stable step %.4g s and %.4g s, %d and %d sub-steps\n", GetParam(),
              solid_->build_report().stable_step, again->build_report().stable_step,
              solid_->build_report().substeps, again->build_report().substeps);
  const Points start = solid_->control_positions();
  solid_->SetAtRest(start);
  again->SetAtRest(start);
  for (int i = 0; i < 200; ++i) {
    ASSERT_OK(solid_->Step());
    ASSERT_OK(again->Step());
  }
  const double moved = (solid_->control_positions() - start).cwiseAbs().maxCoeff();
  const double apart = (solid_->control_positions() - again->control_positions()).cwiseAbs().maxCoeff();
  std::printf("%s: in 0.2 s the bar moved %.3g m; the two solids are %.3g m apart (sub-steps %d, %d)\n",
              GetParam(), moved, apart, solid_->last_step().substeps, again->last_step().substeps);
  EXPECT_GT(moved, 1e-4);
  if (solid_->last_step().substeps == again->last_step().substeps) {
    EXPECT_EQ(apart, 0.0);
  } else {
    EXPECT_LT(apart, 1e-3 * moved);
  }
}

TEST_P(DesignSceneTest, ADesignThatDoesNotFitItsSceneIsRefusedNamingTheField) {
  const Scene design = DesignScene(scene_, *solid_);
  Scene finer = design;
  finer.mutable_subdivision()->set_levels(2);
  EXPECT_THAT(Build(finer).status(),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("design.elements: [")));
  Scene bad_run = design;
  bad_run.mutable_design()->set_sample_runs(1, design.design().materials_size());
  EXPECT_THAT(Build(bad_run).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("design.sample_runs[1]: material")));
  Scene short_runs = design;
  short_runs.mutable_design()->mutable_sample_runs()->RemoveLast();
  EXPECT_THAT(Build(short_runs).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("design.sample_runs")));
  Scene soft = design;
  soft.mutable_design()->mutable_materials(0)->set_young_modulus(-1);
  EXPECT_THAT(Build(soft).status(),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("design.materials[0].young_modulus: -1 is not > 0")));
  Scene laws = design;
  laws.mutable_design()->mutable_cell_flow()->RemoveLast();
  EXPECT_THAT(Build(laws).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("design.cell_flow: ")));
  Scene offsets = design;
  offsets.mutable_design()->add_plastic_offsets(0);
  EXPECT_THAT(Build(offsets).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("design.plastic_offsets: ")));
}

// An edit of a solid created from a saved design drops the design (the
// edited solid carries its materials), and a scene without a design is
// the scene it always was.
TEST_P(DesignSceneTest, AnEditOfASavedDesignCarriesItsMaterials) {
  const Scene design = DesignScene(scene_, *solid_);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<solid::Solid> again, Build(design));
  TopologyEdit sub;
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString("subdivide_cells { cells: 5 }", &sub));
  ASSERT_OK_AND_ASSIGN(AppliedEdit edited, ApplyEdit(design, *again, sub));
  EXPECT_FALSE(edited.scene.has_design());
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<solid::Solid> rebuilt, BuildEdited(edited.scene, 2));
  ASSERT_OK(rebuilt->RestoreState(edited.solid->SaveState()));
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(edited.solid->SaveDesign(),
                                                                 rebuilt->SaveDesign()));
}

INSTANTIATE_TEST_SUITE_P(Corotation, DesignSceneTest, ::testing::Values("CONTROL_CELL", "ELEMENT"),
                         [](const ::testing::TestParamInfo<const char*>& info) {
                           return std::string(info.param);
                         });

}  // namespace
}  // namespace dynsolid::sculpt
