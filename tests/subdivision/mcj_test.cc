#include "solver/subdivision/mcj.h"

#include <cmath>
#include <map>
#include <set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "tests/testing/meshes.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::subdivision {
namespace {

using ::dynsolid::testing::Grid;
using mesh::CellComplex;

std::shared_ptr<const CellComplex> Build(const mesh::MeshInput& in) {
  auto m = CellComplex::FromInput(in);
  EXPECT_OK(m);
  return std::make_shared<const CellComplex>(*std::move(m));
}

SubdivisionOptions Checked() {
  SubdivisionOptions o;
  o.validate_geometry = true;
  return o;
}

SubdivisionOptions Local(std::vector<int32_t> cells) {
  SubdivisionOptions o = Checked();
  o.cells = std::move(cells);
  return o;
}

void ExpectRowsSumToOne(const SparseMatrix& a, const char* what) {
  for (int32_t r = 0; r < a.rows(); ++r) {
    double s = 0.0;
    for (SparseMatrix::InnerIterator it(a, r); it; ++it) s += it.value();
    ASSERT_NEAR(s, 1.0, 1e-12) << what << ": row " << r << " of A sums to " << s;
  }
}

// 1D cubic B-spline refinement mask: weight of coarse index c for fine index f.
double Mask1d(int f, int c) {
  if (f % 2 == 0) {
    const int d = c - f / 2;
    return d == 0 ? 6.0 / 8.0 : (std::abs(d) == 1 ? 1.0 / 8.0 : 0.0);
  }
  const int d = c - (f - 1) / 2;
  return (d == 0 || d == 1) ? 0.5 : 0.0;
}

TEST(MacCrackenJoyTest, RegularGridIsTensorProductCubicBSpline) {
  const int n = 4;
  auto m = Build(Grid(n, n, n));
  auto level = SubdivideOnce(*m, {});
  ASSERT_OK(level);
  const SparseMatrix& a = level->a;
  ASSERT_EQ(a.rows(), 9 * 9 * 9);
  int checked = 0;
  for (int32_t r = 0; r < a.rows(); ++r) {
    // Fine points of interior stencils sit at dyadic grid positions.
    const Eigen::Vector3d p = level->fine.positions().row(r);
    int f[3];
    bool interior = true;
    for (int k = 0; k < 3; ++k) {
      f[k] = static_cast<int>(std::lround(2.0 * p[k]));
      // Stencil supports must be away from the boundary (coarse 1..n-1).
      interior &= f[k] >= 2 && f[k] <= 2 * n - 2;
    }
    if (!interior) continue;
    // Boundary-adjacent fine points use interior rules only if their old
    // element is interior: fine index 2 or 2n-2 are interior vertices.
    std::map<int32_t, double> row;
    for (SparseMatrix::InnerIterator it(a, r); it; ++it) row[it.col()] = it.value();
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; j <= n; ++j) {
        for (int k = 0; k <= n; ++k) {
          const double expected = Mask1d(f[0], i) * Mask1d(f[1], j) * Mask1d(f[2], k);
          const int32_t col = i + (n + 1) * (j + (n + 1) * k);
          const double got = row.count(col) ? row[col] : 0.0;
          ASSERT_NEAR(got, expected, 1e-12)
              << "weight of coarse (" << i << "," << j << "," << k << ") in fine ("
              << f[0] << "," << f[1] << "," << f[2] << ")";
        }
      }
    }
    ++checked;
  }
  // All fine points whose stencils are interior: indices 2..6 per axis.
  EXPECT_EQ(checked, 5 * 5 * 5);
}

TEST(MacCrackenJoyTest, PaperMasks) {
  // The numbers docs/model.md quotes, read off one interior vertex, edge, face
  // and cell point of a 4x4x4 grid.
  auto m = Build(Grid(4, 4, 4));
  auto level = SubdivideOnce(*m, {});
  ASSERT_OK(level);
  auto weights_of = [&](Eigen::Vector3d at) {
    std::multiset<long> w;
    for (int32_t r = 0; r < level->a.rows(); ++r) {
      if ((level->fine.positions().row(r).transpose() - at).norm() > 1e-9) continue;
      for (SparseMatrix::InnerIterator it(level->a, r); it; ++it) {
        w.insert(std::lround(it.value() * 512.0));
      }
    }
    return w;
  };
  const auto vw = weights_of({2, 2, 2});
  EXPECT_EQ(vw.count(216), 1u);
  EXPECT_EQ(vw.count(36), 6u);
  EXPECT_EQ(vw.count(6), 12u);
  EXPECT_EQ(vw.count(1), 8u);
  const auto ew = weights_of({2.5, 2, 2});  // 36/128 = 144/512 per end point
  EXPECT_EQ(ew.count(144), 2u);
  const auto fw = weights_of({2.5, 2.5, 2});  // 3/16 = 96/512, 1/32 = 16/512
  EXPECT_EQ(fw.count(96), 4u);
  EXPECT_EQ(fw.count(16), 8u);
  const auto cw = weights_of({2.5, 2.5, 2.5});  // 1/8 = 64/512
  EXPECT_EQ(cw.count(64), 8u);
}

TEST(MacCrackenJoyTest, RowsSumToOneOverLevels) {
  auto m = Build(Grid(3, 2, 2));
  auto h = Subdivide(m, 3, {});
  ASSERT_OK(h);
  ExpectRowsSumToOne(h->a, "grid 3x2x2, 3 levels");
  EXPECT_EQ(h->fine->num_cells(), 12 * 512);
  // Translating the control points translates every fine point.
  Points p = m->positions();
  p.rowwise() += Eigen::RowVector3d(0.5, -2.0, 7.0);
  const Points d0 = h->a * m->positions();
  const Points d1 = h->a * p;
  EXPECT_NEAR(((d1 - d0).rowwise() - Eigen::RowVector3d(0.5, -2.0, 7.0)).cwiseAbs().maxCoeff(),
              0.0, 1e-12);
}

TEST(MacCrackenJoyTest, Block3TwoLevels) {
  auto m = Build(Grid(3, 3, 3));
  auto h = Subdivide(m, 2, {});
  ASSERT_OK(h);
  EXPECT_EQ(h->fine->num_cells(), 1728);
  EXPECT_EQ(h->fine->num_vertices(), 2197);
  EXPECT_EQ(h->a.rows(), 2197);
  EXPECT_EQ(h->a.cols(), 64);
  ExpectRowsSumToOne(h->a, "block3 level 2");
  EXPECT_EQ(h->fine->CountBoundary().euler(), 2);
  // Every fine cell is a hexahedron with positive volume.
  for (int32_t c = 0; c < h->fine->num_cells(); ++c) {
    ASSERT_TRUE(h->fine->CellIsHexahedron(c)) << "fine cell " << c;
    ASSERT_GT(h->fine->CellVolume(c), 0.0) << "fine cell " << c;
  }
}

TEST(MacCrackenJoyTest, PyramidApexBecomesIrregularCell) {
  auto m = Build(::dynsolid::testing::Pyramid());
  auto level = SubdivideOnce(*m, Checked());
  ASSERT_OK(level);
  ASSERT_EQ(level->fine.num_cells(), 5);
  int hexes = 0, irregular = 0;
  for (int32_t c = 0; c < 5; ++c) {
    if (level->fine.CellIsHexahedron(c)) {
      ++hexes;
      continue;
    }
    ++irregular;
    ASSERT_EQ(level->fine.cell_faces(c).size(), 8u) << "apex cell faces";
    for (int32_t f : level->fine.cell_faces(c)) {
      EXPECT_EQ(level->fine.face_vertices(f).size(), 4u) << "apex cell face " << f;
    }
    EXPECT_EQ(level->fine.cell_vertices(c).size(), 10u);
  }
  EXPECT_EQ(hexes, 4);
  EXPECT_EQ(irregular, 1);
  ExpectRowsSumToOne(level->a, "pyramid");
  // Every face after one level is a quad.
  for (int32_t f = 0; f < level->fine.num_faces(); ++f) {
    EXPECT_EQ(level->fine.face_vertices(f).size(), 4u);
  }
}

TEST(MacCrackenJoyTest, TetrahedronGivesFourHexahedra) {
  auto m = Build(::dynsolid::testing::Tetrahedron());
  auto level = SubdivideOnce(*m, Checked());
  ASSERT_OK(level);
  EXPECT_EQ(level->fine.num_cells(), 4);
  for (int32_t c = 0; c < 4; ++c) EXPECT_TRUE(level->fine.CellIsHexahedron(c));
}

TEST(MacCrackenJoyTest, BoundaryIsCatmullClark) {
  // The boundary vertex rule on a cube corner of valence 3 and a flat
  // boundary vertex: a flat regular boundary patch stays in its plane.
  auto m = Build(Grid(4, 4, 4));
  auto level = SubdivideOnce(*m, {});
  ASSERT_OK(level);
  const auto& f = level->fine;
  for (int32_t v = 0; v < f.num_vertices(); ++v) {
    if (!f.vertex_is_boundary(v)) continue;
    const Eigen::Vector3d p = f.positions().row(v);
    // Points away from the cube's edges stay on the face planes z = 0 etc.
    int on_plane = 0, near_edge = 0;
    for (int k = 0; k < 3; ++k) {
      if (std::abs(p[k]) < 1e-12 || std::abs(p[k] - 4.0) < 1e-12) ++on_plane;
      if (p[k] < 1.0 - 1e-9 || p[k] > 3.0 + 1e-9) ++near_edge;
    }
    if (near_edge == 1) {
      EXPECT_EQ(on_plane, 1) << "flat boundary point " << p.transpose();
    }
  }
  // Catmull-Clark on the valence-3 corner (0,0,0): (Fbar + 2 Rbar + 0 V)/3.
  const Eigen::Vector3d expected = (Eigen::Vector3d(0.5, 0.5, 0) + Eigen::Vector3d(0.5, 0, 0.5) +
                                    Eigen::Vector3d(0, 0.5, 0.5)) / 9.0 +
                                   2.0 * (Eigen::Vector3d(0.5, 0, 0) + Eigen::Vector3d(0, 0.5, 0) +
                                          Eigen::Vector3d(0, 0, 0.5)) / 9.0;
  EXPECT_NEAR((f.positions().row(0).transpose() - expected).norm(), 0.0, 1e-12);
}

TEST(MacCrackenJoyTest, SharpCreasesKeepCubeEdgesStraight) {
  auto m = Build(Grid(2, 2, 2));
  std::vector<uint8_t> tags;
  TagCreases(*m, 60.0, tags);
  int tagged = 0;
  for (uint8_t t : tags) tagged += t;
  EXPECT_EQ(tagged, 24) << "12 cube edges, 2 control edges each";
  auto h = Subdivide(m, 2, tags);
  ASSERT_OK(h);
  const Points& p = h->fine->positions();
  // Corners (three sharp edges) stay put.
  for (int32_t v : {0, 2, 6, 8, 18, 20, 24, 26}) {
    EXPECT_NEAR((p.row(v) - m->positions().row(v)).norm(), 0.0, 1e-12) << "corner " << v;
  }
  // Points on the cube's sharp edges stay on the straight edge.
  int on_edges = 0;
  for (int32_t e = 0; e < h->fine->num_edges(); ++e) {
    if (!h->sharp_edges[e]) continue;
    for (int32_t v : h->fine->edge_vertices(e)) {
      const Eigen::Vector3d q = p.row(v);
      int extreme = 0;
      for (int k = 0; k < 3; ++k) {
        extreme += (std::abs(q[k]) < 1e-12 || std::abs(q[k] - 2.0) < 1e-12) ? 1 : 0;
      }
      EXPECT_GE(extreme, 2) << "sharp-edge point " << q.transpose() << " left the cube edge";
      ++on_edges;
    }
  }
  EXPECT_EQ(on_edges, 12 * 8 * 2);  // 12 edges x 8 fine segments x 2 ends
}

TEST(MacCrackenJoyTest, SharpEdgesFromPairsRejectsNonEdges) {
  auto m = Build(Grid(1, 1, 1));
  EXPECT_OK(SharpEdgesFromPairs(*m, {{0, 1}}));
  EXPECT_THAT(SharpEdgesFromPairs(*m, {{0, 6}}),
              ::dynsolid::testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                            ::testing::HasSubstr("(0 6) is not an edge")));
  EXPECT_THAT(SharpEdgesFromPairs(*m, {{0, 60}}),
              ::dynsolid::testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                            ::testing::HasSubstr("out of range")));
}

TEST(MacCrackenJoyTest, LocalSubdivisionKeepsNeighbours) {
  auto m = Build(Grid(3, 1, 1));
  auto level = SubdivideOnce(*m, Local({1}));
  ASSERT_OK(level);
  const auto& f = level->fine;
  EXPECT_EQ(f.num_cells(), 2 + 8);
  ExpectRowsSumToOne(level->a, "local subdivision");
  // Unrefined cells keep their vertices, their volume, and see the split
  // face as four quads: 5 + 4 faces.
  for (int32_t c = 0; c < f.num_cells(); ++c) {
    if (level->parent_cell[c] == 1) continue;
    EXPECT_EQ(f.cell_faces(c).size(), 9u) << "neighbour cell " << c;
    EXPECT_NEAR(f.CellVolume(c), 1.0, 1e-12) << "neighbour cell " << c << " changed shape";
  }
  for (int32_t v = 0; v < m->num_vertices(); ++v) {
    EXPECT_NEAR((f.positions().row(v) - m->positions().row(v)).norm(), 0.0, 1e-12)
        << "control vertex " << v << " moved (all touch an unrefined cell)";
  }
  EXPECT_EQ(f.CountBoundary().euler(), 2);
}

// Subdivision builds its fine levels without checking their cells'
// closedness (closed by construction from closed parents): every level of
// uniform and local subdivisions of hexahedra, a pyramid, a tetrahedron
// and a sharp-edged block is checked here.
TEST(MacCrackenJoyTest, EveryLevelsCellsAreClosed) {
  std::vector<std::shared_ptr<const CellComplex>> inputs = {
      Build(Grid(3, 2, 2)), Build(::dynsolid::testing::Pyramid()),
      Build(::dynsolid::testing::Tetrahedron())};
  for (size_t i = 0; i < inputs.size(); ++i) {
    auto h = Subdivide(inputs[i], 3, {});
    ASSERT_OK(h);
    EXPECT_OK(h->fine->CheckCellsClosed()) << "input " << i << " at 3 levels";
    for (int levels = 1; levels < 3; ++levels) {
      auto coarser = Subdivide(inputs[i], levels, {});
      ASSERT_OK(coarser);
      EXPECT_OK(coarser->fine->CheckCellsClosed()) << "input " << i << " at " << levels;
    }
    // Locally refined (the first cell), then subdivided twice.
    SubdivisionOptions local;
    local.cells = {0};
    auto refined = SubdivideOnce(*inputs[i], local);
    ASSERT_OK(refined);
    EXPECT_OK(refined->fine.CheckCellsClosed()) << "input " << i << " refined locally";
    auto after = Subdivide(std::make_shared<const CellComplex>(refined->fine), 2, {});
    ASSERT_OK(after);
    EXPECT_OK(after->fine->CheckCellsClosed()) << "input " << i << " refined, 2 levels";
  }
  // Sharp edges change the rules, not the topology; a block with all its
  // boundary edges sharp, 2 levels.
  auto block = inputs[0];
  std::vector<uint8_t> sharp(block->num_edges(), 0);
  for (int32_t e = 0; e < block->num_edges(); ++e) {
    for (int32_t f : block->edge_faces(e)) sharp[e] |= block->face_is_boundary(f) ? 1 : 0;
  }
  auto h = Subdivide(block, 2, sharp);
  ASSERT_OK(h);
  EXPECT_OK(h->fine->CheckCellsClosed());
}

// The check itself: a cell missing a face is refused by name.
TEST(MacCrackenJoyTest, AnOpenCellIsFound) {
  mesh::MeshInput in = Grid(1, 1, 1);
  ASSERT_EQ(in.cells.size(), 1u);
  in.cells[0].pop_back();  // five faces of a cube: open
  auto m = CellComplex::FromInput(in);
  EXPECT_THAT(m, ::dynsolid::testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                               ::testing::HasSubstr("is not closed")));
}

TEST(MacCrackenJoyTest, LocalSubdivisionRejectsBadCell) {
  auto m = Build(Grid(2, 1, 1));
  EXPECT_THAT(SubdivideOnce(*m, Local({5})),
              ::dynsolid::testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                            ::testing::HasSubstr("cell 5 is out of range")));
}

}  // namespace
}  // namespace dynsolid::subdivision
