// subdivision::EstimateFineCells: the cells MacCracken-Joy makes, counted
// without a mesh, against the cells it does make.
#include <span>
#include <string>

#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/subdivision/cell_count.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::subdivision {
namespace {

std::span<const int32_t> Refined(const Scene& scene) {
  const auto& r = scene.mesh().refine_cells();
  return {r.data(), static_cast<size_t>(r.size())};
}

TEST(CellVertexValencesTest, AHexahedronHasEightVerticesOfValenceThree) {
  const std::vector<std::vector<int32_t>> cube = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                                  {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
  EXPECT_EQ(CellVertexValences(cube), std::vector<int64_t>(8, 3));
  // A hexahedron's vertex child is a hexahedron: 8^(L-1) at level L.
  EXPECT_EQ(DescendantsOfVertexChild(3, 1), 1);
  EXPECT_EQ(DescendantsOfVertexChild(3, 3), 64);
}

// The estimate against the built count on every built-in scene: exact
// without local refinement, also for cells that are not hexahedra (mixed
// has a pyramid whose apex has valence 4, a prism and a tetrahedron).
TEST(EstimateFineCellsTest, MatchesTheBuiltCellCountOfEveryBuiltinScene) {
  for (const std::string& name : scene::BuiltinSceneNames()) {
    absl::StatusOr<Scene> scene = scene::BuiltinScene(name);
    ASSERT_OK(scene);
    absl::StatusOr<mesh::MeshInput> control =
        scene::ControlMeshInput(*scene, scene::BuiltinSceneDir());
    ASSERT_OK(control);
    for (int levels = 0; levels <= 2; ++levels) {
      absl::StatusOr<scene::Discretization> d = scene::Discretize(*scene, *control, levels);
      ASSERT_OK(d);
      const int64_t estimate = EstimateFineCells(*control, Refined(*scene), levels);
      if (scene->mesh().refine_cells_size() == 0) {
        EXPECT_EQ(estimate, d->fine().num_cells()) << name << " at " << levels << " levels";
      } else {
        // Refinement adds vertices to the neighbours' faces, which the
        // estimate ignores: it may fall short, by at most a quarter here.
        EXPECT_LE(estimate, d->fine().num_cells()) << name << " at " << levels << " levels";
        EXPECT_GE(estimate, 0.75 * d->fine().num_cells())
            << name << " at " << levels << " levels";
      }
    }
  }
}

// With local refinement the estimate ignores the vertices refinement adds
// to the neighbours' faces, so it may fall a little short.
TEST(EstimateFineCellsTest, StaysCloseWithLocalRefinement) {
  absl::StatusOr<Scene> scene = scene::ParseScene(
      "mesh { block { nx: 3 ny: 3 nz: 3 } refine_cells: [0, 13] }", "refined");
  ASSERT_OK(scene);
  absl::StatusOr<mesh::MeshInput> control = scene::ControlMeshInput(*scene, "");
  ASSERT_OK(control);
  for (int levels = 0; levels <= 2; ++levels) {
    absl::StatusOr<scene::Discretization> d = scene::Discretize(*scene, *control, levels);
    ASSERT_OK(d);
    const double cells = d->fine().num_cells();
    const int64_t estimate = EstimateFineCells(*control, Refined(*scene), levels);
    EXPECT_LE(estimate, cells) << "at " << levels << " levels";
    EXPECT_GE(estimate, 0.8 * cells) << "at " << levels << " levels";
  }
}

}  // namespace
}  // namespace dynsolid::subdivision
