#include "solver/scene/generators.h"

#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Geometry>
#include <google/protobuf/text_format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/mesh/cell_complex.h"
#include "tests/scene/mesh_input_checks.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::scene {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

using ::dynsolid::testing::Parse;

// What a generated mesh must be, checked twice: by the independent
// reference (CheckMeshInput) and by CellComplex::FromInput.
struct Expected {
  int64_t cells;
  int64_t vertices;
  int64_t boundary_euler;  // 2 per sphere-like boundary, 0 per torus, 2 - 2g
  double volume;           // total, m^3; < 0: not checked
};

void ExpectValidMesh(const mesh::MeshInput& input, const Expected& expected) {
  EXPECT_EQ(static_cast<int64_t>(input.cells.size()), expected.cells) << "cell count";
  EXPECT_EQ(input.vertices.rows(), expected.vertices) << "vertex count";
  EXPECT_OK(testing::CheckMeshInput(input));
  EXPECT_EQ(testing::CountComponents(input), 1) << "connected components";
  for (const auto& cell : input.cells) {
    ASSERT_EQ(cell.size(), 6u) << "generators make hexahedra";
    for (const auto& loop : cell) ASSERT_EQ(loop.size(), 4u);
  }

  absl::StatusOr<mesh::CellComplex> complex = mesh::CellComplex::FromInput(input);
  ASSERT_OK(complex);
  EXPECT_EQ(complex->num_cells(), expected.cells);
  EXPECT_EQ(complex->num_vertices(), expected.vertices);
  double total = 0;
  for (int32_t c = 0; c < complex->num_cells(); ++c) {
    const double v = complex->CellVolume(c);
    EXPECT_GT(v, 0) << "volume of cell " << c;
    EXPECT_NEAR(v, testing::CellVolume(input, c), 1e-12 * (1 + std::abs(v)))
        << "volume of cell " << c << ": CellComplex vs reference";
    EXPECT_TRUE(complex->CellIsHexahedron(c)) << "cell " << c;
    total += v;
  }
  if (expected.volume >= 0) {
    EXPECT_NEAR(total, expected.volume, 1e-9 * expected.volume) << "total volume";
  }
  EXPECT_EQ(complex->CountBoundary().euler(), expected.boundary_euler)
      << "boundary Euler characteristic";
  // Every boundary loop (as stored, outward) has area: a sanity check that
  // no face is degenerate.
  for (int32_t f = 0; f < complex->num_faces(); ++f) {
    const auto loop = complex->face_vertices(f);
    const Eigen::Vector3d a = complex->positions().row(loop[0]);
    const Eigen::Vector3d b = complex->positions().row(loop[1]);
    const Eigen::Vector3d c = complex->positions().row(loop[2]);
    EXPECT_GT((b - a).cross(c - a).norm(), 0) << "face " << f;
  }
}

// ----------------------------------------------------------------- block

TEST(GenerateBlockTest, Block3HasUnitCellsAndSphereBoundary) {
  absl::StatusOr<mesh::MeshInput> m = GenerateBlock(Parse<BlockGenerator>("nx: 3 ny: 3 nz: 3"));
  ASSERT_OK(m);
  ExpectValidMesh(*m, {.cells = 27, .vertices = 64, .boundary_euler = 2, .volume = 27});
  // Vertex (i, j, k) is i + 4 (j + 4 k) and sits at (i, j, k).
  EXPECT_EQ(m->vertices.row(1 + 4 * (2 + 4 * 3)), Eigen::RowVector3d(1, 2, 3));
  EXPECT_EQ(m->vertices.row(63), Eigen::RowVector3d(3, 3, 3));
  absl::StatusOr<mesh::CellComplex> complex = mesh::CellComplex::FromInput(*m);
  ASSERT_OK(complex);
  EXPECT_EQ(complex->num_faces(), 108) << "27 * 6 - 54 shared";
  EXPECT_EQ(complex->num_edges(), 144);
  const auto boundary = complex->CountBoundary();
  EXPECT_EQ(boundary.faces, 54);
  EXPECT_EQ(boundary.vertices, 56);
}

TEST(GenerateBlockTest, SizeAndOriginPlaceTheBox) {
  absl::StatusOr<mesh::MeshInput> m = GenerateBlock(Parse<BlockGenerator>(
      "nx: 2 ny: 1 nz: 4 size { x: 1 y: 0.5 z: 2 } origin { x: -1 y: 0 z: 3 }"));
  ASSERT_OK(m);
  ExpectValidMesh(*m, {.cells = 8, .vertices = 30, .boundary_euler = 2, .volume = 1.0});
  EXPECT_EQ(m->vertices.row(0), Eigen::RowVector3d(-1, 0, 3));
  EXPECT_EQ(m->vertices.row(29), Eigen::RowVector3d(0, 0.5, 5));
}

TEST(GenerateBlockTest, RejectsBadParameters) {
  struct Case {
    std::string text;
    std::string message;
  };
  const Case cases[] = {
      {"nx: 0 ny: 3 nz: 3", "block.nx must be >= 1, got 0"},
      {"nx: 3 ny: -2 nz: 3", "block.ny must be >= 1, got -2"},
      {"nx: 3 ny: 3", "block.nz must be >= 1, got 0"},
      {"nx: 1 ny: 1 nz: 1 size { x: 1 y: 0 z: 1 }", "block.size.y must be > 0"},
      {"nx: 1 ny: 1 nz: 1 size { x: -1 y: 1 z: 1 }", "block.size.x must be > 0"},
      {"nx: 1 ny: 1 nz: 1 size { x: inf y: 1 z: 1 }", "block.size.x must be finite, got inf"},
      {"nx: 1 ny: 1 nz: 1 origin { z: nan }", "block.origin.z must be finite"},
      {"nx: 1000 ny: 1000 nz: 1000", "more than the limit of 1000000"},
      {"nx: 2000000000 ny: 2000000000 nz: 2000000000", "block would have"},
  };
  for (const Case& c : cases) {
    EXPECT_THAT(GenerateBlock(Parse<BlockGenerator>(c.text)),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(c.message)))
        << c.text;
  }
}

// ------------------------------------------------------------------ beam

TEST(GenerateBeamTest, CantileverBeam) {
  absl::StatusOr<mesh::MeshInput> m = GenerateBeam(Parse<BeamGenerator>(
      "length: 1 width: 0.1 height: 0.1 cells_along: 10 cells_across: 1"));
  ASSERT_OK(m);
  ExpectValidMesh(*m, {.cells = 10, .vertices = 44, .boundary_euler = 2, .volume = 0.01});
  EXPECT_DOUBLE_EQ(m->vertices.col(0).minCoeff(), 0.0);
  EXPECT_DOUBLE_EQ(m->vertices.col(0).maxCoeff(), 1.0);
  EXPECT_DOUBLE_EQ(m->vertices.col(1).minCoeff(), -0.05);
  EXPECT_DOUBLE_EQ(m->vertices.col(2).maxCoeff(), 0.05);
  // The clamped face x = 0: vertices 0, 11, 22, 33.
  for (int v : {0, 11, 22, 33}) EXPECT_EQ(m->vertices(v, 0), 0.0) << "vertex " << v;
}

// Each case's text, parsed as a G, is refused by `generate` as
// InvalidArgument with the case's message in its text.
template <typename G, typename Generate, size_t N>
void ExpectRefused(Generate generate, const std::pair<std::string, std::string> (&cases)[N]) {
  for (const auto& [text, message] : cases) {
    EXPECT_THAT(generate(Parse<G>(text)),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(message)))
        << text;
  }
}

TEST(GenerateBeamTest, RejectsBadParameters) {
  const std::pair<std::string, std::string> cases[] = {
      {"width: 0.1 height: 0.1 cells_along: 10 cells_across: 1", "beam.length must be > 0, got 0"},
      {"length: 1 width: -0.1 height: 0.1 cells_along: 10 cells_across: 1",
       "beam.width must be > 0, got -0.1"},
      {"length: 1 width: 0.1 height: nan cells_along: 10 cells_across: 1",
       "beam.height must be finite"},
      {"length: 1 width: 0.1 height: 0.1 cells_across: 1", "beam.cells_along must be >= 1, got 0"},
      {"length: 1 width: 0.1 height: 0.1 cells_along: 3", "beam.cells_across must be >= 1, got 0"},
      {"length: 1 width: 1 height: 1 cells_along: 100000 cells_across: 100",
       "more than the limit"},
  };
  ExpectRefused<BeamGenerator>(GenerateBeam, cases);
}

// ------------------------------------------------------------------ tube

TEST(GenerateTubeTest, NozzleIsPeriodicAndNarrows) {
  absl::StatusOr<mesh::MeshInput> m = GenerateTube(Parse<TubeGenerator>(
      "segments: 11 layers: 1 slices: 9 inner_radius: 0.3 outer_radius: 0.5 length: 1.5 "
      "end_scale: 0.5"));
  ASSERT_OK(m);
  // The ring closes: 11 vertex columns, not 12 with a seam. The boundary is a
  // torus (inner wall, outer wall, two end rings).
  ExpectValidMesh(*m, {.cells = 99, .vertices = 2 * 11 * 10, .boundary_euler = 0, .volume = -1});
  // No two vertices coincide (a seam would).
  for (int a = 0; a < m->vertices.rows(); ++a) {
    for (int b = a + 1; b < m->vertices.rows(); ++b) {
      ASSERT_GT((m->vertices.row(a) - m->vertices.row(b)).norm(), 1e-6) << a << " " << b;
    }
  }
  // Vertex (l, s, k) = l + 2 (s + 11 k); radii scale to 0.5 at z = length.
  auto radius = [&](int v) { return m->vertices.row(v).head<2>().norm(); };
  EXPECT_NEAR(radius(0), 0.3, 1e-12);
  EXPECT_NEAR(radius(1), 0.5, 1e-12);
  EXPECT_NEAR(radius(0 + 2 * (3 + 11 * 9)), 0.15, 1e-12);
  EXPECT_NEAR(radius(1 + 2 * (3 + 11 * 9)), 0.25, 1e-12);
  EXPECT_NEAR(m->vertices(1 + 2 * (3 + 11 * 9), 2), 1.5, 1e-12);
}

TEST(GenerateTubeTest, StraightTubeVolumeIsThePrismaticAnnulus) {
  const int segments = 8;
  absl::StatusOr<mesh::MeshInput> m = GenerateTube(Parse<TubeGenerator>(
      "segments: 8 layers: 2 slices: 3 inner_radius: 1 outer_radius: 2 length: 3"));
  ASSERT_OK(m);
  // Polygonal annulus: area of a regular n-gon of circumradius r is
  // n r^2 sin(2 pi / n) / 2.
  const double ngon = segments * std::sin(2 * std::numbers::pi / segments) / 2;
  ExpectValidMesh(*m, {.cells = 48, .vertices = 3 * 8 * 4, .boundary_euler = 0,
                       .volume = ngon * (4 - 1) * 3});
}

TEST(GenerateTubeTest, RejectsBadParameters) {
  const std::pair<std::string, std::string> cases[] = {
      {"segments: 11 layers: 1 slices: 9 inner_radius: 2 outer_radius: 1 length: 1",
       "tube.inner_radius (2) must be less than tube.outer_radius (1)"},
      {"segments: 11 layers: 1 slices: 9 inner_radius: 1 outer_radius: 1 length: 1",
       "tube.inner_radius (1) must be less than tube.outer_radius (1)"},
      {"segments: 2 layers: 1 slices: 9 inner_radius: 1 outer_radius: 2 length: 1",
       "tube.segments must be >= 3, got 2"},
      {"segments: 11 slices: 9 inner_radius: 1 outer_radius: 2 length: 1",
       "tube.layers must be >= 1, got 0"},
      {"segments: 11 layers: 1 inner_radius: 1 outer_radius: 2 length: 1",
       "tube.slices must be >= 1, got 0"},
      {"segments: 11 layers: 1 slices: 9 outer_radius: 2 length: 1",
       "tube.inner_radius must be > 0, got 0"},
      {"segments: 11 layers: 1 slices: 9 inner_radius: 1 outer_radius: 2",
       "tube.length must be > 0, got 0"},
      {"segments: 11 layers: 1 slices: 9 inner_radius: 1 outer_radius: 2 length: 1 "
       "end_scale: -0.5",
       "tube.end_scale must be > 0 (0 means 1, a straight tube), got -0.5"},
      {"segments: 1000 layers: 1000 slices: 1000 inner_radius: 1 outer_radius: 2 length: 1",
       "more than the limit"},
  };
  ExpectRefused<TubeGenerator>(GenerateTube, cases);
}

// ----------------------------------------------------------------- torus

TEST(GenerateTorusTest, HandleHasTorusBoundary) {
  absl::StatusOr<mesh::MeshInput> m = GenerateTorus(Parse<TorusGenerator>(
      "major_radius: 1 tube_half_width: 0.35 segments: 12 cross: 2"));
  ASSERT_OK(m);
  // Each cell column is a prism over a trapezoid: the segment between
  // angles -a and a (a = pi / 12) has area sin(a) cos(a) (ro^2 - ri^2), so
  // the volume is 12 * h * sin(2a) / 2 * (ro^2 - ri^2) with h = 0.7,
  // ro = 1.35, ri = 0.65.
  const double volume = 12 * 0.7 * std::sin(std::numbers::pi / 6) / 2 * (1.35 * 1.35 - 0.65 * 0.65);
  ExpectValidMesh(*m, {.cells = 48, .vertices = 12 * 9, .boundary_euler = 0, .volume = volume});
  // Periodic: 12 columns, and cell (i, s, j) = i + 2 (j + 2 s) has corner
  // vertices in columns s and s + 1 mod 12.
  const auto& last = m->cells[1 + 2 * (1 + 2 * 11)];
  bool touches_column0 = false;
  for (const auto& loop : last) {
    for (int32_t v : loop) touches_column0 |= v < 9;
  }
  EXPECT_TRUE(touches_column0) << "the last segment wraps to the first";
}

TEST(GenerateTorusTest, RejectsBadParameters) {
  const std::pair<std::string, std::string> cases[] = {
      {"major_radius: 1 tube_half_width: 2 segments: 12 cross: 2",
       "torus.tube_half_width (2) must be less than torus.major_radius (1)"},
      {"major_radius: 1 tube_half_width: 0.5 segments: 2 cross: 2",
       "torus.segments must be >= 3, got 2"},
      {"major_radius: 1 tube_half_width: 0.5 segments: 12",
       "torus.cross must be >= 1, got 0"},
      {"tube_half_width: 0.5 segments: 12 cross: 1", "torus.major_radius must be > 0, got 0"},
      {"major_radius: 1 segments: 12 cross: 1", "torus.tube_half_width must be > 0, got 0"},
      {"major_radius: 1 tube_half_width: 0.5 segments: 100000 cross: 100",
       "more than the limit"},
  };
  ExpectRefused<TorusGenerator>(GenerateTorus, cases);
}

// ---------------------------------------------------------------- voxels

TEST(GenerateVoxelsTest, SharedGridVerticesAreMerged) {
  absl::StatusOr<mesh::MeshInput> m =
      GenerateVoxels(Parse<VoxelGenerator>("boxes { x1: 2 y1: 1 z1: 1 }"));
  ASSERT_OK(m);
  ExpectValidMesh(*m, {.cells = 2, .vertices = 12, .boundary_euler = 2, .volume = 2});
}

TEST(GenerateVoxelsTest, UnionMinusSubtractedWithUnusedVerticesDropped) {
  // A 3 x 3 x 3 box minus its middle column (a hole through z): a thick
  // ring whose boundary is a torus; every grid vertex is still used.
  absl::StatusOr<mesh::MeshInput> ring = GenerateVoxels(Parse<VoxelGenerator>(
      "cell_size: 0.5 boxes { x1: 3 y1: 3 z1: 3 } "
      "boxes { x0: 1 y0: 1 z0: 0 x1: 2 y1: 2 z1: 3 subtract: true }"));
  ASSERT_OK(ring);
  ExpectValidMesh(*ring, {.cells = 24, .vertices = 64, .boundary_euler = 0, .volume = 24 * 0.125});

  // An L whose bounding box has unused grid vertices: 3 voxels, 16 vertices
  // (the 3 x 3 x 2 grid of the bounding box has 18).
  absl::StatusOr<mesh::MeshInput> ell = GenerateVoxels(
      Parse<VoxelGenerator>("boxes { x1: 2 y1: 2 z1: 1 } "
                            "boxes { x0: 1 y0: 1 x1: 2 y1: 2 z1: 1 subtract: true } "
                            "boxes { x0: 0 y0: 0 z0: 0 x1: 1 y1: 1 z1: 1 }"));
  ASSERT_OK(ell);
  ExpectValidMesh(*ell, {.cells = 3, .vertices = 16, .boundary_euler = 2, .volume = 3});
}

TEST(GenerateVoxelsTest, CellsAreInZYXOrderAndScaled) {
  absl::StatusOr<mesh::MeshInput> m = GenerateVoxels(Parse<VoxelGenerator>(
      "cell_size: 0.25 boxes { x0: -1 y0: 0 z0: 2 x1: 1 y1: 2 z1: 3 }"));
  ASSERT_OK(m);
  ASSERT_EQ(m->cells.size(), 4u);
  // Cell order (z, y, x): the first cell is voxel (-1, 0, 2), the second
  // (0, 0, 2); their centroids differ by one cell along x.
  auto centroid = [&](int c) {
    Eigen::RowVector3d sum = Eigen::RowVector3d::Zero();
    for (const auto& loop : m->cells[c]) {
      for (int32_t v : loop) sum += m->vertices.row(v);
    }
    return Eigen::RowVector3d(sum / 24.0);
  };
  EXPECT_TRUE(centroid(0).isApprox(Eigen::RowVector3d(-0.125, 0.125, 0.625)));
  EXPECT_TRUE(centroid(1).isApprox(Eigen::RowVector3d(0.125, 0.125, 0.625)));
  EXPECT_TRUE(centroid(2).isApprox(Eigen::RowVector3d(-0.125, 0.375, 0.625)));
}

TEST(GenerateVoxelsTest, ChairAndBridge) {
  absl::StatusOr<mesh::MeshInput> chair = GenerateVoxels(Parse<VoxelGenerator>(R"pb(
    cell_size: 0.1
    boxes { x0: 0 y0: 0 z0: 0 x1: 1 y1: 1 z1: 4 }
    boxes { x0: 4 y0: 0 z0: 0 x1: 5 y1: 1 z1: 4 }
    boxes { x0: 0 y0: 4 z0: 0 x1: 1 y1: 5 z1: 4 }
    boxes { x0: 4 y0: 4 z0: 0 x1: 5 y1: 5 z1: 4 }
    boxes { x0: 0 y0: 0 z0: 4 x1: 5 y1: 5 z1: 5 }
    boxes { x0: 0 y0: 4 z0: 5 x1: 5 y1: 5 z1: 12 }
  )pb"));
  ASSERT_OK(chair);
  ExpectValidMesh(*chair, {.cells = 76, .vertices = 220, .boundary_euler = 2, .volume = 0.076});

  absl::StatusOr<mesh::MeshInput> bridge = GenerateVoxels(Parse<VoxelGenerator>(R"pb(
    cell_size: 0.5
    boxes { x0: 0 y0: 0 z0: 4 x1: 30 y1: 3 z1: 5 }
    boxes { x0: 0 y0: 0 z0: 0 x1: 2 y1: 3 z1: 4 }
    boxes { x0: 14 y0: 0 z0: 0 x1: 16 y1: 3 z1: 4 }
    boxes { x0: 28 y0: 0 z0: 0 x1: 30 y1: 3 z1: 4 }
    boxes { x0: 5 y0: 1 z0: 4 x1: 9 y1: 2 z1: 5 subtract: true }
    boxes { x0: 21 y0: 1 z0: 4 x1: 25 y1: 2 z1: 5 subtract: true }
  )pb"));
  ASSERT_OK(bridge);
  // Two openings through the deck: genus 2, Euler 2 - 2 * 2.
  ExpectValidMesh(*bridge,
                  {.cells = 154, .vertices = 392, .boundary_euler = -2, .volume = 154 * 0.125});
}

TEST(GenerateVoxelsTest, RejectsBadParametersAndResults) {
  const std::pair<std::string, std::string> cases[] = {
      {"", "voxels.boxes is empty"},
      {"boxes { x1: 1 y1: 1 z1: 1 subtract: true }", "every box has subtract: true"},
      {"boxes { x1: 1 y1: 1 z1: 1 } boxes { x0: 5 x1: 3 y1: 1 z1: 1 }",
       "voxels.boxes[1].x1 (3) must be greater than voxels.boxes[1].x0 (5)"},
      {"boxes { x1: 1 y1: 1 }", "voxels.boxes[0].z1 (0) must be greater than voxels.boxes[0].z0 (0)"},
      {"cell_size: -1 boxes { x1: 1 y1: 1 z1: 1 }", "voxels.cell_size must be > 0 (0 means 1), got -1"},
      {"boxes { x1: 2 y1: 2 z1: 1 } boxes { x0: -1 y0: -1 z0: -1 x1: 3 y1: 3 z1: 3 subtract: true }",
       "no voxel remains"},
      // Two voxels sharing only an edge.
      {"boxes { x1: 1 y1: 1 z1: 1 } boxes { x0: 1 y0: 1 x1: 2 y1: 2 z1: 1 }",
       "not a manifold at grid vertex (1, 1, 0)"},
      // Two voxels sharing only a corner.
      {"boxes { x1: 1 y1: 1 z1: 1 } boxes { x0: 1 y0: 1 z0: 1 x1: 2 y1: 2 z1: 2 }",
       "not a manifold at grid vertex (1, 1, 1)"},
      // A 2x2x2 block missing two opposite corners touches itself at the centre.
      {"boxes { x1: 2 y1: 2 z1: 2 } boxes { x1: 1 y1: 1 z1: 1 subtract: true } "
       "boxes { x0: 1 y0: 1 z0: 1 x1: 2 y1: 2 z1: 2 subtract: true }",
       "not a manifold at grid vertex (1, 1, 1)"},
      {"boxes { x0: -100000 x1: 100000 y1: 1000 z1: 1 }", "more than the limit of 64000000"},
      {"boxes { x1: 200 y1: 100 z1: 100 }", "more than the limit of 1000000"},
      {"boxes { x1: 400 y1: 400 z1: 400 } boxes { x1: 400 y1: 400 z1: 400 } "
       "boxes { x1: 400 y1: 400 z1: 400 } boxes { x1: 400 y1: 400 z1: 400 } "
       "boxes { x1: 400 y1: 400 z1: 400 }",
       "more than the limit of 256000000"},
  };
  ExpectRefused<VoxelGenerator>(GenerateVoxels, cases);
}

TEST(ValidateTest, ValidateAgreesWithGenerate) {
  EXPECT_OK(ValidateBlock(Parse<BlockGenerator>("nx: 1 ny: 1 nz: 1")));
  EXPECT_THAT(ValidateTube(Parse<TubeGenerator>(
                  "segments: 11 layers: 1 slices: 9 inner_radius: 2 outer_radius: 1 length: 1")),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("tube.inner_radius (2) must be less than tube.outer_radius (1)")));
  EXPECT_OK(ValidateVoxels(Parse<VoxelGenerator>("boxes { x1: 1 y1: 1 z1: 1 }")));
}

}  // namespace
}  // namespace dynsolid::scene
