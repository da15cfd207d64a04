#include "solver/mesh/cell_complex.h"

#include <cmath>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "solver/mesh/boundary.h"
#include "tests/testing/meshes.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::mesh {
namespace {

using ::dynsolid::testing::Grid;
using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

TEST(CellComplexTest, SingleHexCountsAndVolume) {
  auto m = CellComplex::FromInput(Grid(1, 1, 1, 2.0));
  ASSERT_OK(m);
  EXPECT_EQ(m->num_vertices(), 8);
  EXPECT_EQ(m->num_edges(), 12);
  EXPECT_EQ(m->num_faces(), 6);
  EXPECT_EQ(m->num_cells(), 1);
  EXPECT_TRUE(m->CellIsHexahedron(0));
  EXPECT_NEAR(m->CellVolume(0), 8.0, 1e-12) << "volume of a 2 m cube";
  EXPECT_EQ(m->CountBoundary().euler(), 2);
  for (int32_t e = 0; e < 12; ++e) {
    EXPECT_EQ(m->edge_faces(e).size(), 2u);
    EXPECT_EQ(m->edge_cells(e).size(), 1u);
    EXPECT_TRUE(m->edge_is_boundary(e));
  }
}

TEST(CellComplexTest, GridAdjacency) {
  auto m = CellComplex::FromInput(Grid(2, 2, 2));
  ASSERT_OK(m);
  EXPECT_EQ(m->num_vertices(), 27);
  EXPECT_EQ(m->num_cells(), 8);
  EXPECT_EQ(m->num_faces(), 36);  // 3 * 3 * 2 * 2
  EXPECT_EQ(m->num_edges(), 54);  // 3 * 3 * 3 * 2
  const int32_t center = 13;
  EXPECT_FALSE(m->vertex_is_boundary(center));
  EXPECT_EQ(m->vertex_edges(center).size(), 6u);
  EXPECT_EQ(m->vertex_faces(center).size(), 12u);
  EXPECT_EQ(m->vertex_cells(center).size(), 8u);
  // Interior edge from the centre up: 4 faces, 4 cells in radial order,
  // consecutive faces sharing the cell between them.
  const int32_t e = m->FindEdge(center, center + 9);
  ASSERT_GE(e, 0);
  EXPECT_FALSE(m->edge_is_boundary(e));
  const auto faces = m->edge_faces(e);
  const auto cells = m->edge_cells(e);
  ASSERT_EQ(faces.size(), 4u);
  ASSERT_EQ(cells.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    const auto& a = m->face_cells(faces[i]);
    const auto& b = m->face_cells(faces[(i + 1) % 4]);
    const int32_t c = cells[i];
    EXPECT_TRUE((a[0] == c || a[1] == c) && (b[0] == c || b[1] == c))
        << "cell " << c << " lies between radial faces " << i << " and " << i + 1;
  }
  // Interior faces have two cells that see opposite loops.
  int interior = 0;
  for (int32_t f = 0; f < m->num_faces(); ++f) interior += m->face_is_boundary(f) ? 0 : 1;
  EXPECT_EQ(interior, 12);
  EXPECT_EQ(m->CountBoundary().euler(), 2);
}

TEST(CellComplexTest, BoundaryExtractionIsOutward) {
  auto m = CellComplex::FromInput(Grid(2, 1, 1));
  ASSERT_OK(m);
  const BoundarySurface s = ExtractBoundary(*m);
  EXPECT_EQ(s.faces.rows(), 10);
  EXPECT_EQ(s.positions.rows(), 12);
  // Closed outward surface: the divergence theorem gives the volume.
  double six_v = 0.0;
  for (int32_t f = 0; f < s.faces.rows(); ++f) {
    const auto loop = s.faces.row(f);
    const Eigen::Vector3d a = s.positions.row(loop[0]);
    for (size_t i = 1; i + 1 < loop.size(); ++i) {
      const Eigen::Vector3d b = s.positions.row(loop[i]);
      const Eigen::Vector3d c = s.positions.row(loop[i + 1]);
      six_v += a.dot(b.cross(c));
    }
  }
  EXPECT_NEAR(six_v / 6.0, 2.0, 1e-12) << "enclosed volume of the boundary surface";
}

// ---- Every bad-mesh rule of docs/model.md section 1, with its message. ----

// FromInput refuses `in` as InvalidArgument with `message` in its text.
void ExpectRefused(const MeshInput& in, const std::string& message) {
  EXPECT_THAT(CellComplex::FromInput(in),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(message)));
}

TEST(CellComplexValidationTest, NonFiniteCoordinate) {
  MeshInput in = Grid(1, 1, 1);
  in.vertices(5, 1) = NAN;
  ExpectRefused(in, "vertex 5 has a non-finite coordinate y");
}

TEST(CellComplexValidationTest, Empty) {
  MeshInput in = Grid(1, 1, 1);
  in.cells.clear();
  ExpectRefused(in, "mesh has no cells");
  MeshInput none;
  EXPECT_THAT(CellComplex::FromInput(none),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("no vertices")));
}

TEST(CellComplexValidationTest, IndexOutOfRange) {
  MeshInput in = Grid(1, 1, 1);
  in.cells[0][2][1] = 99;
  ExpectRefused(in, "cell 0 face 2: vertex index 99 is out of range [0, 8)");
}

TEST(CellComplexValidationTest, RepeatedVertexInLoop) {
  MeshInput in = Grid(1, 1, 1);
  in.cells[0][1] = {4, 5, 6, 5};
  ExpectRefused(in, "cell 0 face 1: vertex 5 is repeated in the face loop");
}

TEST(CellComplexValidationTest, FaceInThreeCells) {
  MeshInput in = Grid(2, 1, 1);
  // Cells 0 and 1 share the face x = 1 (vertices 1 4 10 7); a third cell
  // built on the same face claims it too.
  const int32_t nv = static_cast<int32_t>(in.vertices.rows());
  in.vertices.conservativeResize(nv + 4, 3);
  in.vertices.bottomRows(4) << 1, 0, -2, 1, 1, -2, 1, 0, -1, 1, 1, -1;
  in.cells.push_back(::dynsolid::testing::HexFaces({1, nv, nv + 1, 4, 7, nv + 2, nv + 3, 10}));
  ExpectRefused(in, "is shared by cells 0, 1 and 2; a face belongs to at most two "
                    "cells");
}

TEST(CellComplexValidationTest, OpenCell) {
  MeshInput in = Grid(1, 1, 1);
  in.cells[0].pop_back();
  ExpectRefused(in, "cell 0 is not closed: edge");
}

TEST(CellComplexValidationTest, InconsistentOrientationInsideCell) {
  MeshInput in = Grid(1, 1, 1);
  std::reverse(in.cells[0][3].begin(), in.cells[0][3].end());
  ExpectRefused(in, "inconsistent orientation: cell 0 faces");
}

TEST(CellComplexValidationTest, InconsistentOrientationBetweenCells) {
  MeshInput in = Grid(2, 1, 1);
  for (auto& loop : in.cells[1]) std::reverse(loop.begin(), loop.end());
  ExpectRefused(in, "inconsistent orientation: cells 0 and 1 share face");
}

TEST(CellComplexValidationTest, NegativeVolume) {
  MeshInput in = Grid(1, 1, 1);
  for (auto& loop : in.cells[0]) std::reverse(loop.begin(), loop.end());
  ExpectRefused(in, "cell 0 has negative volume");
}

TEST(CellComplexValidationTest, ZeroVolume) {
  MeshInput in = Grid(1, 1, 1);
  for (int v = 0; v < 8; ++v) in.vertices(v, 2) = 0.0;  // flattened
  ExpectRefused(in, "cell 0 has zero volume");
}

TEST(CellComplexValidationTest, TooFewFacesOrVertices) {
  MeshInput in = Grid(1, 1, 1);
  in.cells[0][0] = {0, 3};
  ExpectRefused(in, "cell 0 face 0 has 2 vertices");
}

TEST(CellComplexValidationTest, UnusedVertex) {
  MeshInput in = Grid(1, 1, 1);
  in.vertices.conservativeResize(9, 3);
  in.vertices.row(8) << 5, 5, 5;
  ExpectRefused(in, "vertex 8 belongs to no cell");
  // Dropping it renumbers nothing that is used here, and the mesh builds.
  EXPECT_EQ(DropUnusedVertices(in), 1);
  EXPECT_OK(CellComplex::FromInput(in));
}

TEST(CellComplexValidationTest, DropUnusedVerticesRenumbers) {
  MeshInput in = Grid(1, 1, 1);
  // Put an unused vertex first: every used index shifts down by one.
  Points v(9, 3);
  v.row(0) << -7, -7, -7;
  v.bottomRows(8) = in.vertices;
  in.vertices = v;
  for (auto& face : in.cells[0])
    for (int32_t& x : face) ++x;
  EXPECT_EQ(DropUnusedVertices(in), 1);
  auto m = CellComplex::FromInput(in);
  ASSERT_OK(m);
  EXPECT_NEAR(m->CellVolume(0), 1.0, 1e-12);
  EXPECT_EQ(in.vertices(0, 0), 0.0);
}

TEST(CellComplexValidationTest, OriginPrefixesMessages) {
  MeshInput in = Grid(1, 1, 1);
  in.origin = "scenes/broken.vtk";
  in.cells[0].pop_back();
  ExpectRefused(in, "scenes/broken.vtk: cell 0 is not closed");
}

}  // namespace
}  // namespace dynsolid::mesh
