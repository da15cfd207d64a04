// Topology edits on hand-counted voxel meshes (docs/model.md section 8).
#include "solver/sculpt/topology.h"

#include <cmath>
#include <cstring>
#include <span>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/sculpt/voxel_mesh.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::sculpt {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::AllOf;
using testing::Block;
using testing::BoundaryFaceAt;
using testing::CountBoundaryFaces;
using testing::FaceAt;
using ::testing::HasSubstr;
using testing::Voxels;
using Vec = Eigen::Vector3d;

const std::vector<uint8_t> kNoSharp;

mesh::CellComplex Make(const mesh::MeshInput& input) {
  absl::StatusOr<mesh::CellComplex> c = mesh::CellComplex::FromInput(input);
  EXPECT_TRUE(c.ok()) << c.status();
  return *std::move(c);
}

// Invariants every result must have: sizes agree, sources are rows of old
// vertices summing to 1, the mesh rebuilds with positive volumes.
void ExpectConsistent(const EditResult& r, int32_t old_vertices, int32_t old_cells) {
  const int32_t nv = static_cast<int32_t>(r.mesh.vertices.rows());
  ASSERT_EQ(r.current.rows(), nv) << "current rows";
  ASSERT_EQ(static_cast<int32_t>(r.vertex_sources.size()), nv) << "vertex_sources rows";
  ASSERT_EQ(r.cell_source.size(), r.mesh.cells.size()) << "cell_source size";
  for (int32_t v = 0; v < nv; ++v) {
    double sum = 0.0;
    for (const auto& [old, w] : r.vertex_sources[v]) {
      ASSERT_GE(old, 0);
      ASSERT_LT(old, old_vertices);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-12) << "vertex_sources[" << v << "] weight sum";
  }
  for (int32_t c : r.cell_source) {
    EXPECT_GE(c, -1);
    EXPECT_LT(c, old_cells);
  }
  const mesh::CellComplex built = Make(r.mesh);
  for (int32_t c = 0; c < built.num_cells(); ++c)
    EXPECT_GT(built.CellVolume(c), 0.0) << "cell " << c;
}

// With current == rest in, current == mesh.vertices out (1e-12: subdivision
// computes positions and stencils separately).
void ExpectCurrentIsRest(const EditResult& r) {
  ASSERT_EQ(r.current.rows(), r.mesh.vertices.rows());
  EXPECT_LT((r.current - r.mesh.vertices).cwiseAbs().maxCoeff(), 1e-12)
      << "current positions differ from rest ones though current == rest went in";
}

Points Rotated(const Points& p, double degrees) {
  const double a = degrees * M_PI / 180.0;
  Eigen::Matrix3d r;
  r << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  return p * r.transpose();
}

class Block3Test : public ::testing::Test {
 protected:
  // Extrudes `faces` of the block at rest (no sharp tags) by `distance` in
  // `layers`; a result is checked consistent with the block.
  absl::StatusOr<EditResult> ExtrudeAtRest(std::span<const int32_t> faces, double distance,
                                           int layers) {
    absl::StatusOr<EditResult> r = ExtrudeFaces(block_, rest_, kNoSharp, faces, distance, layers);
    if (r.ok()) ExpectConsistent(*r, 64, 27);
    return r;
  }

  mesh::CellComplex block_ = Make(Block(3, 3, 3));
  Points rest_ = block_.positions();
};

TEST_F(Block3Test, ExtrudeOneFaceOneLayer) {
  const int32_t f = BoundaryFaceAt(block_, Vec(1.5, 1.5, 3.0));
  ASSERT_GE(f, 0);
  const int32_t faces[] = {f};
  absl::StatusOr<EditResult> r = ExtrudeAtRest(faces, 0.25, 1);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->mesh.cells.size(), 28u) << "+1 cell";
  EXPECT_EQ(r->mesh.vertices.rows(), 68) << "+4 vertices";
  EXPECT_EQ(r->summary, "extruded 1 face by 0.25 m in 1 layer: +1 cell, +4 vertices");
  const mesh::CellComplex out = Make(r->mesh);
  const int32_t g = FaceAt(out, Vec(1.5, 1.5, 3.0));
  ASSERT_GE(g, 0);
  EXPECT_FALSE(out.face_is_boundary(g)) << "the extruded face is interior after";
  EXPECT_NEAR(out.CellVolume(27), 1.0 * 0.25, 1e-12) << "new cell volume = area x d";
  EXPECT_TRUE(out.CellIsHexahedron(27));
  EXPECT_EQ(r->cell_source[27], -1);
  EXPECT_EQ(r->cell_source[5], 5);
  EXPECT_EQ(CountBoundaryFaces(out), 54 - 1 + 5);
  // current == rest in gives current == mesh.vertices out.
  EXPECT_EQ(r->current, r->mesh.vertices);
  // New vertices come from the face's vertices and sit d above them.
  for (int32_t v = 64; v < 68; ++v) {
    ASSERT_EQ(r->vertex_sources[v].size(), 1u);
    const int32_t src = r->vertex_sources[v][0].first;
    EXPECT_NEAR((r->mesh.vertices.row(v) - rest_.row(src)).norm(), 0.25, 1e-15);
    EXPECT_DOUBLE_EQ(r->mesh.vertices(v, 2), 3.25);
  }
}

TEST_F(Block3Test, ExtrudeTwoLayers) {
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(0.5, 0.0, 1.5))};  // a -y face
  absl::StatusOr<EditResult> r = ExtrudeAtRest(faces, 0.5, 2);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->mesh.cells.size(), 29u) << "+2 cells";
  EXPECT_EQ(r->mesh.vertices.rows(), 72) << "+8 vertices";
  const mesh::CellComplex out = Make(r->mesh);
  EXPECT_NEAR(out.CellVolume(27), 0.25, 1e-12);
  EXPECT_NEAR(out.CellVolume(28), 0.25, 1e-12);
  EXPECT_NEAR(r->mesh.vertices.col(1).minCoeff(), -0.5, 1e-15);
}

TEST_F(Block3Test, ExtrudePatchSharesSideFaces) {
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(0.5, 0.5, 3.0)),
                           BoundaryFaceAt(block_, Vec(1.5, 0.5, 3.0))};
  absl::StatusOr<EditResult> r = ExtrudeAtRest(faces, 1.0, 1);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->mesh.cells.size(), 29u) << "+2 cells";
  EXPECT_EQ(r->mesh.vertices.rows(), 70) << "+6 vertices (one shared side)";
  const mesh::CellComplex out = Make(r->mesh);
  // The shared side quad at x = 1 between the two new cells is interior.
  const int32_t side = FaceAt(out, Vec(1.0, 0.5, 3.5));
  ASSERT_GE(side, 0);
  EXPECT_FALSE(out.face_is_boundary(side));
  EXPECT_EQ(CountBoundaryFaces(out), 54 - 2 + 2 + 6);
}

TEST_F(Block3Test, ExtrudeFollowsTheDeformedSolid) {
  const Points current = Rotated(rest_, 30.0);
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(3.0, 1.5, 1.5)),
                           BoundaryFaceAt(block_, Vec(3.0, 2.5, 1.5))};
  absl::StatusOr<EditResult> r = ExtrudeFaces(block_, current, kNoSharp, faces, 0.3, 3);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 64, 27);
  const Points expected = Rotated(r->mesh.vertices, 30.0);
  EXPECT_LT((r->current - expected).cwiseAbs().maxCoeff(), 1e-12)
      << "current positions = rest result rotated by 30 degrees about z";
}

TEST_F(Block3Test, ExtrudeRefusals) {
  const int32_t interior = FaceAt(block_, Vec(1.0, 1.5, 1.5));
  ASSERT_GE(interior, 0);
  const int32_t top = BoundaryFaceAt(block_, Vec(1.5, 1.5, 3.0));
  const int32_t bad_interior[] = {top, interior};
  EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, bad_interior, 0.1, 1),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("faces[1]: face " + std::to_string(interior)),
                             HasSubstr("interior"))));
  const int32_t out_of_range[] = {top, 999};
  EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, out_of_range, 0.1, 1),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("faces[1]: face 999 is out of range [0, 108)")));
  const int32_t repeated[] = {top, top};
  EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, repeated, 0.1, 1),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("faces[1]")));
  const int32_t one[] = {top};
  for (double d : {0.0, -1.0, std::nan(""), double{INFINITY}}) {
    EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, one, d, 1),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("distance")))
        << "distance " << d;
  }
  for (int layers : {0, -1, kMaxExtrudeLayers + 1}) {
    EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, one, 0.1, layers),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("layers")));
  }
  Points bad = rest_;
  bad(7, 1) = std::nan("");
  EXPECT_THAT(ExtrudeFaces(block_, bad, kNoSharp, one, 0.1, 1),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("current[7]")));
  EXPECT_THAT(ExtrudeFaces(block_, rest_.topRows(10), kNoSharp, one, 0.1, 1),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("current")));
}

TEST_F(Block3Test, DeleteCornerCell) {
  const int32_t cells[] = {0};  // voxel (0, 0, 0)
  absl::StatusOr<EditResult> r = DeleteCells(block_, rest_, kNoSharp, cells);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 64, 27);
  EXPECT_EQ(r->mesh.cells.size(), 26u) << "-1 cell";
  EXPECT_EQ(r->mesh.vertices.rows(), 63) << "-1 vertex: the corner only";
  const mesh::CellComplex out = Make(r->mesh);
  // 3 boundary faces go with the cell, 3 faces it shared become boundary.
  EXPECT_EQ(CountBoundaryFaces(out), 54);
  EXPECT_EQ(out.CountBoundary().euler(), 2);
  // Survivors renumbered in old order: old vertex 1 is new vertex 0.
  EXPECT_EQ(r->vertex_sources[0][0].first, 1);
  EXPECT_EQ(r->vertex_sources[62][0].first, 63);
  EXPECT_EQ(r->cell_source[0], 1);
  EXPECT_EQ(r->current, r->mesh.vertices);
  EXPECT_EQ(r->summary, "deleted 1 cell: -1 vertex, 26 cells left");
}

TEST_F(Block3Test, DeleteCentreMakesACavity) {
  const int32_t cells[] = {13};  // voxel (1, 1, 1)
  absl::StatusOr<EditResult> r = DeleteCells(block_, rest_, kNoSharp, cells);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 64, 27);
  ExpectCurrentIsRest(*r);
  EXPECT_EQ(r->mesh.vertices.rows(), 64) << "every vertex still used";
  const mesh::CellComplex out = Make(r->mesh);
  EXPECT_EQ(CountBoundaryFaces(out), 60);
  EXPECT_EQ(out.CountBoundary().euler(), 4) << "outer sphere + cavity sphere";
}

TEST_F(Block3Test, DeleteRefusals) {
  std::vector<int32_t> all(27);
  for (int32_t c = 0; c < 27; ++c) all[c] = c;
  EXPECT_THAT(DeleteCells(block_, rest_, kNoSharp, all),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("all 27 cells")));
  const int32_t out_of_range[] = {3, 99};
  EXPECT_THAT(DeleteCells(block_, rest_, kNoSharp, out_of_range),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("cells[1]: cell 99 is out of range [0, 27)")));
  const int32_t repeated[] = {3, 4, 3};
  EXPECT_THAT(DeleteCells(block_, rest_, kNoSharp, repeated),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("cells[2]: cell 3 is repeated (also cells[0])")));
  EXPECT_THAT(DeleteCells(block_, rest_, kNoSharp, {}),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("cells")));
}

TEST(DeleteTest, RefusesCellsTouchingAlongAnEdge) {
  const mesh::CellComplex block = Make(Block(2, 2, 1));
  const int32_t cells[] = {1, 2};  // leaves voxels (0,0,0) and (1,1,0)
  EXPECT_THAT(DeleteCells(block, block.positions(), kNoSharp, cells),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("delete: non-manifold"), HasSubstr("edge"))));
}

TEST(DeleteTest, RefusesCellsTouchingAtAVertex) {
  const mesh::CellComplex block = Make(Block(2, 2, 2));
  const int32_t cells[] = {1, 2, 3, 4, 5, 6};  // leaves voxels (0,0,0) and (1,1,1)
  EXPECT_THAT(DeleteCells(block, block.positions(), kNoSharp, cells),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("delete: non-manifold"), HasSubstr("vertex"),
                             HasSubstr("(1, 1, 1)"))));
}

TEST(DeleteTest, SplittingIntoTwoComponentsIsAllowed) {
  const mesh::CellComplex beam = Make(Block(3, 1, 1));
  const int32_t cells[] = {1};
  absl::StatusOr<EditResult> r = DeleteCells(beam, beam.positions(), kNoSharp, cells);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 16, 3);
  ExpectCurrentIsRest(*r);
  EXPECT_EQ(Make(r->mesh).CountBoundary().euler(), 4);
}

TEST(MergeTest, JoinsTwoBlocks) {
  const mesh::CellComplex two = Make(Voxels({{0, 0, 0}, {2, 0, 0}}));
  ASSERT_EQ(two.CountBoundary().euler(), 4);
  const int32_t a = BoundaryFaceAt(two, Vec(1.0, 0.5, 0.5));
  const int32_t b = BoundaryFaceAt(two, Vec(2.0, 0.5, 0.5));
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  absl::StatusOr<EditResult> r = MergeFaces(two, two.positions(), kNoSharp, a, b);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 16, 2);
  ExpectCurrentIsRest(*r);
  const mesh::CellComplex out = Make(r->mesh);
  EXPECT_EQ(out.num_cells(), 3);
  EXPECT_EQ(out.num_vertices(), 16) << "merge adds no vertex";
  EXPECT_EQ(out.CountBoundary().euler(), 2) << "one component";
  EXPECT_NEAR(out.CellVolume(2), 1.0, 1e-12);
  EXPECT_TRUE(out.CellIsHexahedron(2));
  EXPECT_FALSE(out.face_is_boundary(FaceAt(out, Vec(1.0, 0.5, 0.5))));
  EXPECT_FALSE(out.face_is_boundary(FaceAt(out, Vec(2.0, 0.5, 0.5))));
  EXPECT_THAT(r->summary, AllOf(HasSubstr("joined two components"), HasSubstr("4 -> 2")));
  // Either order of the faces gives a valid cell.
  EXPECT_TRUE(MergeFaces(two, two.positions(), kNoSharp, b, a).ok());
}

TEST(MergeTest, RefusesACellInvertedInTheCurrentConfiguration) {
  const mesh::CellComplex two = Make(Voxels({{0, 0, 0}, {2, 0, 0}}));
  // Currently the second block has moved to the left of the first one.
  Points current = two.positions();
  for (int32_t v = 0; v < current.rows(); ++v) {
    if (current(v, 0) >= 2.0) current(v, 0) -= 4.0;
  }
  EXPECT_THAT(MergeFaces(two, current, kNoSharp, BoundaryFaceAt(two, Vec(1.0, 0.5, 0.5)),
                         BoundaryFaceAt(two, Vec(2.0, 0.5, 0.5))),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("merge: new cell 2"), HasSubstr("current"))));
}

TEST(ExtrudeTest, TriangleAndPentagonFacesMakePrisms) {
  // A pentagonal prism of height 1; extruding its top gives a second one.
  mesh::MeshInput input;
  input.vertices.resize(10, 3);
  for (int i = 0; i < 5; ++i) {
    const double a = 2.0 * M_PI * i / 5.0;
    input.vertices.row(i) << std::cos(a), std::sin(a), 0.0;
    input.vertices.row(i + 5) << std::cos(a), std::sin(a), 1.0;
  }
  std::vector<std::vector<int32_t>> faces = {{0, 4, 3, 2, 1}, {5, 6, 7, 8, 9}};
  for (int i = 0; i < 5; ++i) faces.push_back({i, (i + 1) % 5, (i + 1) % 5 + 5, i + 5});
  input.cells = {faces};
  const mesh::CellComplex prism = Make(input);
  const int32_t top = BoundaryFaceAt(prism, Vec(0, 0, 1));
  ASSERT_GE(top, 0);
  const int32_t one[] = {top};
  absl::StatusOr<EditResult> r = ExtrudeFaces(prism, prism.positions(), kNoSharp, one, 0.5, 1);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 10, 1);
  const mesh::CellComplex out = Make(r->mesh);
  EXPECT_EQ(out.num_vertices(), 15);
  EXPECT_EQ(out.cell_faces(1).size(), 7u) << "2 pentagons + 5 side quads";
  EXPECT_NEAR(out.CellVolume(1), 0.5 * prism.CellVolume(0), 1e-12);

  // A tetrahedron's face becomes a triangular prism of volume area x d.
  mesh::MeshInput tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  tet.cells = {{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}};
  const mesh::CellComplex t = Make(tet);
  const int32_t slanted = BoundaryFaceAt(t, Vec(1.0 / 3, 1.0 / 3, 1.0 / 3));
  const int32_t base[] = {slanted};
  r = ExtrudeFaces(t, t.positions(), kNoSharp, base, 0.2, 1);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 4, 1);
  const mesh::CellComplex prism3 = Make(r->mesh);
  EXPECT_EQ(prism3.num_vertices(), 7);
  EXPECT_EQ(prism3.cell_faces(1).size(), 5u);
  EXPECT_NEAR(prism3.CellVolume(1), std::sqrt(3.0) / 2.0 * 0.2, 1e-12);
}

TEST(MergeTest, MakesAHandle) {
  // A ring of 3 x 3 voxels in the xz plane around (1, 0, 1), open at the
  // top middle (1, 0, 2): the merge closes it.
  const mesh::CellComplex u =
      Make(Voxels({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 0, 1}, {2, 0, 1}, {0, 0, 2}, {2, 0, 2}}));
  ASSERT_EQ(u.CountBoundary().euler(), 2);
  const int32_t a = BoundaryFaceAt(u, Vec(1.0, 0.5, 2.5));
  const int32_t b = BoundaryFaceAt(u, Vec(2.0, 0.5, 2.5));
  absl::StatusOr<EditResult> r = MergeFaces(u, u.positions(), kNoSharp, a, b);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, u.num_vertices(), 7);
  const mesh::CellComplex out = Make(r->mesh);
  EXPECT_EQ(out.CountBoundary().euler(), 0) << "a torus";
  EXPECT_THAT(r->summary, AllOf(HasSubstr("made a handle"), HasSubstr("2 -> 0")));
}

TEST(MergeTest, FillingANotchIsNotAHandle) {
  // A U of five voxels: the merge fills the notch at (1, 0, 1), whose bottom
  // face then also becomes interior; still a ball.
  const mesh::CellComplex u = Make(Voxels({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 0, 1}, {2, 0, 1}}));
  absl::StatusOr<EditResult> r =
      MergeFaces(u, u.positions(), kNoSharp, BoundaryFaceAt(u, Vec(1.0, 0.5, 1.5)),
                 BoundaryFaceAt(u, Vec(2.0, 0.5, 1.5)));
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, u.num_vertices(), 5);
  EXPECT_EQ(Make(r->mesh).CountBoundary().euler(), 2);
  EXPECT_THAT(r->summary, AllOf(HasSubstr("filled a gap"), HasSubstr("2 -> 2")));
}

TEST(MergeTest, Refusals) {
  // A cube and a separate tetrahedron (triangle faces).
  mesh::MeshInput input = Voxels({{0, 0, 0}});
  const int32_t t0 = 8;
  input.vertices.conservativeResize(12, 3);
  input.vertices.bottomRows(4) << 3, 0, 0, 4, 0, 0, 3, 1, 0, 3, 0, 1;
  input.cells.push_back(
      {{t0, t0 + 2, t0 + 1}, {t0, t0 + 1, t0 + 3}, {t0, t0 + 3, t0 + 2}, {t0 + 1, t0 + 2, t0 + 3}});
  const mesh::CellComplex m = Make(input);
  const Points& p = m.positions();
  const int32_t quad = BoundaryFaceAt(m, Vec(1.0, 0.5, 0.5));
  const int32_t tri = m.cell_faces(1)[0];
  EXPECT_THAT(MergeFaces(m, p, kNoSharp, quad, quad),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("face_b: face " + std::to_string(quad))));
  EXPECT_THAT(MergeFaces(m, p, kNoSharp, quad, tri),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("face_b: face " + std::to_string(tri) + " has 3 vertices"),
                             HasSubstr("has 4"))));
  EXPECT_THAT(
      MergeFaces(m, p, kNoSharp, quad, 77),
      StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("face_b: face 77 is out of range")));
  const int32_t other = BoundaryFaceAt(m, Vec(0.5, 0.5, 1.0));  // shares 2 vertices with quad
  EXPECT_THAT(MergeFaces(m, p, kNoSharp, quad, other),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("share vertex")));

  const mesh::CellComplex block = Make(Block(2, 1, 1));
  const int32_t interior = FaceAt(block, Vec(1.0, 0.5, 0.5));
  EXPECT_THAT(MergeFaces(block, block.positions(), kNoSharp, interior,
                         BoundaryFaceAt(block, Vec(2.0, 0.5, 0.5))),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("face_a: face " + std::to_string(interior)),
                             HasSubstr("interior"))));
  // Two opposite faces of one block: the connecting cell would wrap around
  // the block and is inside out (its faces see it from outside): refused.
  const mesh::CellComplex cube = Make(Block(1, 1, 1));
  EXPECT_FALSE(MergeFaces(cube, cube.positions(), kNoSharp,
                          BoundaryFaceAt(cube, Vec(0.5, 0.5, 0.0)),
                          BoundaryFaceAt(cube, Vec(0.5, 0.5, 1.0)))
                   .ok());
}

TEST_F(Block3Test, SubdivideOneCell) {
  const int32_t cells[] = {13};
  Points current = Rotated(rest_, 30.0);
  current.col(2).array() += 0.5;
  absl::StatusOr<EditResult> r = SubdivideCells(block_, current, kNoSharp, cells);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectConsistent(*r, 64, 27);
  EXPECT_EQ(r->mesh.cells.size(), 27u - 1 + 8) << "a hexahedron splits into 8";
  EXPECT_EQ(r->mesh.vertices.rows(), 64 + 12 + 6 + 1) << "+12 edge, +6 face, +1 cell points";
  int children = 0;
  for (int32_t c : r->cell_source) children += c == 13 ? 1 : 0;
  EXPECT_EQ(children, 8);
  // The six face neighbours see their shared face split in 4: 6 - 1 + 4 faces.
  const mesh::CellComplex out = Make(r->mesh);
  int split_neighbours = 0;
  for (int32_t c = 0; c < out.num_cells(); ++c) {
    if (r->cell_source[c] != 13 && out.cell_faces(c).size() == 9) ++split_neighbours;
  }
  EXPECT_EQ(split_neighbours, 6);
  // Current positions follow the same stencils: a rigid motion of the rest result.
  Points expected = Rotated(r->mesh.vertices, 30.0);
  expected.col(2).array() += 0.5;
  EXPECT_LT((r->current - expected).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_THAT(SubdivideCells(block_, rest_, kNoSharp, std::vector<int32_t>{27}),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("cells[0]: cell 27 is out of range [0, 27)")));
}

TEST_F(Block3Test, SharpTagsSurviveEdits) {
  const std::array<int32_t, 2> edge{0, 1};
  absl::StatusOr<EditResult> tagged = SetSharp(block_, rest_, kNoSharp, std::span(&edge, 1), true);
  ASSERT_TRUE(tagged.ok()) << tagged.status();
  ASSERT_EQ(tagged->sharp_edges.size(), 1u);
  EXPECT_EQ(tagged->sharp_edges[0], edge);
  std::vector<uint8_t> tags(block_.num_edges(), 0);
  tags[block_.FindEdge(0, 1)] = 1;
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(1.5, 1.5, 3.0))};
  absl::StatusOr<EditResult> extruded = ExtrudeFaces(block_, rest_, tags, faces, 0.1, 1);
  ASSERT_TRUE(extruded.ok()) << extruded.status();
  EXPECT_EQ(extruded->sharp_edges, tagged->sharp_edges);
  absl::StatusOr<EditResult> untagged = SetSharp(block_, rest_, tags, std::span(&edge, 1), false);
  ASSERT_TRUE(untagged.ok());
  EXPECT_TRUE(untagged->sharp_edges.empty());
  const std::array<int32_t, 2> not_edge{0, 63};
  EXPECT_THAT(
      SetSharp(block_, rest_, kNoSharp, std::span(&not_edge, 1), true),
      StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("edges[0]: (0 63) is not an edge")));
  const int32_t cells[] = {0};
  absl::StatusOr<EditResult> refined = SubdivideCells(block_, rest_, tags, cells);
  ASSERT_TRUE(refined.ok()) << refined.status();
  ExpectConsistent(*refined, 64, 27);
  ExpectCurrentIsRest(*refined);
  EXPECT_EQ(refined->sharp_edges.size(), 2u) << "the tag goes to both child edges";
}

TEST_F(Block3Test, DeleteKeepsSurvivingSharpEdgesRenumbered) {
  std::vector<uint8_t> tags(block_.num_edges(), 0);
  tags[block_.FindEdge(0, 1)] = 1;  // goes with the corner vertex
  tags[block_.FindEdge(1, 2)] = 1;  // survives as (0, 1)
  const int32_t cells[] = {0};
  absl::StatusOr<EditResult> r = DeleteCells(block_, rest_, tags, cells);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->sharp_edges.size(), 1u);
  EXPECT_EQ(r->sharp_edges[0], (std::array<int32_t, 2>{0, 1}));
}

TEST_F(Block3Test, ExtrudingFacesThatMeetAtACornerOnlyIsRefused) {
  // Two top faces diagonal to each other: their new cells would share only
  // the vertical edge over the common corner (non-manifold).
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(0.5, 0.5, 3.0)),
                           BoundaryFaceAt(block_, Vec(1.5, 1.5, 3.0))};
  EXPECT_THAT(ExtrudeFaces(block_, rest_, kNoSharp, faces, 0.5, 1),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("extrude: non-manifold")));
}

TEST_F(Block3Test, Deterministic) {
  const Points current = Rotated(rest_, 17.0);
  const int32_t faces[] = {BoundaryFaceAt(block_, Vec(0.5, 0.5, 3.0)),
                           BoundaryFaceAt(block_, Vec(1.5, 0.5, 3.0))};
  const EditResult a = ExtrudeFaces(block_, current, kNoSharp, faces, 0.3, 2).value();
  const EditResult b = ExtrudeFaces(block_, current, kNoSharp, faces, 0.3, 2).value();
  ASSERT_EQ(a.current.size(), b.current.size());
  EXPECT_EQ(0, std::memcmp(a.current.data(), b.current.data(), a.current.size() * sizeof(double)));
  EXPECT_EQ(a.mesh.cells, b.mesh.cells);
}

}  // namespace
}  // namespace dynsolid::sculpt
