// Scene -> discretization: Table-1 counts, topology kept through the levels,
// local refinement and sharp features from scene fields, determinism.
#include "solver/scene/build.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/scene/scene_loader.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::scene {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

Discretization BuildBuiltin(const std::string& name, std::optional<int> levels = std::nullopt) {
  auto scene = BuiltinScene(name);
  EXPECT_OK(scene);
  auto d = BuildDiscretization(*scene, BuiltinSceneDir(), levels);
  EXPECT_OK(d);
  return *std::move(d);
}

TEST(SceneBuildTest, Block3TwoLevels) {
  const Discretization d = BuildBuiltin("block3");
  EXPECT_EQ(d.control().num_cells(), 27);
  EXPECT_EQ(d.fine().num_cells(), 1728);
  EXPECT_EQ(d.elements.num_nodes(), 2197);
  EXPECT_EQ(d.elements.num_cubic(), 1000);
  EXPECT_EQ(d.node_matrix.rows(), 2197);
  EXPECT_EQ(d.node_matrix.cols(), 64);
  EXPECT_GT(d.sharp_control_edges, 0) << "block3 tags its box edges as creases";
}

TEST(SceneBuildTest, EveryBuiltinSceneKeepsItsTopologyThroughSubdivision) {
  for (const std::string& name : BuiltinSceneNames()) {
    const Discretization d = BuildBuiltin(name);
    // Boundary Euler characteristic is a topological invariant: subdivision
    // keeps holes and handles (torus 0, bridge with two openings -2).
    EXPECT_EQ(d.fine().CountBoundary().euler(), d.control().CountBoundary().euler()) << name;
    // Every row of the node matrix sums to 1 (the solid moves rigidly with
    // its control points).
    for (int32_t r = 0; r < d.node_matrix.rows(); ++r) {
      double s = 0;
      for (subdivision::SparseMatrix::InnerIterator it(d.node_matrix, r); it; ++it) s += it.value();
      ASSERT_NEAR(s, 1.0, 1e-12) << name << " node " << r;
    }
    for (int32_t c = 0; c < d.fine().num_cells(); ++c) {
      ASSERT_GT(d.fine().CellVolume(c), 0.0) << name << " fine cell " << c;
    }
    EXPECT_EQ(d.elements.num_cubic() + d.elements.num_linear() + d.elements.num_pyramid_cells(),
              d.fine().num_cells())
        << name << ": every cell gets exactly one element kind";
  }
}

TEST(SceneBuildTest, TorusKeepsItsHole) {
  const Discretization d = BuildBuiltin("torus", 3);
  EXPECT_EQ(d.fine().CountBoundary().euler(), 0);
  EXPECT_EQ(d.fine().num_cells(), 48 * 512);
}

TEST(SceneBuildTest, MixedMeshHasAllThreeElementKinds) {
  const Discretization d = BuildBuiltin("mixed", 1);
  EXPECT_GT(d.elements.num_linear(), 0);
  EXPECT_EQ(d.elements.num_pyramid_cells(), 1) << "the pyramid's apex cell";
  EXPECT_EQ(d.elements.num_pyramid(), 8);
  const Discretization d2 = BuildBuiltin("mixed", 2);
  EXPECT_GT(d2.elements.num_cubic(), 0);
}

TEST(SceneBuildTest, LocalRefinementFromScene) {
  auto scene = ParseScene(R"pb(
    name: "local"
    mesh { block { nx: 3 ny: 1 nz: 1 } refine_cells: 1 }
    subdivision { levels: 0 }
  )pb", "test");
  ASSERT_OK(scene);
  auto d = BuildDiscretization(*scene, "", std::nullopt);
  ASSERT_OK(d);
  EXPECT_EQ(d->input_cells, 3);
  EXPECT_EQ(d->locally_refined_cells, 1);
  EXPECT_EQ(d->control().num_cells(), 10);
  EXPECT_EQ(d->elements.num_pyramid_cells(), 2) << "the two neighbours became 9-faced cells";
}

TEST(SceneBuildTest, BadSharpEdgeNamesTheField) {
  auto scene = ParseScene(R"pb(
    name: "sharp"
    mesh { block { nx: 1 ny: 1 nz: 1 } }
    sharp { edges { v0: 0 v1: 7 } }
  )pb", "test");
  ASSERT_OK(scene);
  EXPECT_THAT(BuildDiscretization(*scene, "", std::nullopt),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("sharp.edges: sharp edge 0 (0 7) is not an edge")));
}

TEST(SceneBuildTest, LevelsOutOfRange) {
  auto scene = BuiltinScene("block3");
  ASSERT_OK(scene);
  EXPECT_THAT(BuildDiscretization(*scene, "", 7),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("levels must be in 0..4")));
}

TEST(SceneBuildTest, Deterministic) {
  const Discretization a = BuildBuiltin("chair");
  const Discretization b = BuildBuiltin("chair");
  ASSERT_EQ(a.node_matrix.nonZeros(), b.node_matrix.nonZeros());
  for (int64_t i = 0; i < a.node_matrix.nonZeros(); ++i) {
    ASSERT_EQ(a.node_matrix.valuePtr()[i], b.node_matrix.valuePtr()[i]);
    ASSERT_EQ(a.node_matrix.innerIndexPtr()[i], b.node_matrix.innerIndexPtr()[i]);
  }
  EXPECT_EQ(a.elements.cubic_nodes, b.elements.cubic_nodes);
  EXPECT_EQ(a.elements.linear_nodes, b.elements.linear_nodes);
}

}  // namespace
}  // namespace dynsolid::scene
