#include "solver/fem/element_set.h"

#include <set>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "tests/testing/meshes.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::fem {
namespace {

using ::dynsolid::testing::Grid;
using mesh::CellComplex;

subdivision::Hierarchy Refine(const mesh::MeshInput& in, int levels) {
  auto m = CellComplex::FromInput(in);
  EXPECT_OK(m);
  auto h = subdivision::Subdivide(std::make_shared<const CellComplex>(*std::move(m)), levels, {});
  EXPECT_OK(h);
  return *std::move(h);
}

TEST(ElementSetTest, Block3TwoLevelsTableOne) {
  const auto h = Refine(Grid(3, 3, 3), 2);
  const ElementSet e = ClassifyElements(*h.fine);
  EXPECT_EQ(h.fine->num_cells(), 1728);
  EXPECT_EQ(e.num_nodes(), 2197);
  EXPECT_EQ(e.num_cubic(), 1000) << "cubic B-spline elements (57.9 %)";
  EXPECT_EQ(e.num_linear(), 728);
  EXPECT_EQ(e.num_pyramid(), 0);
  EXPECT_NEAR(100.0 * e.num_cubic() / h.fine->num_cells(), 57.87, 0.01);
}

TEST(ElementSetTest, CubicNodesFormTheFourByFourByFourBlock) {
  const auto h = Refine(Grid(4, 4, 4), 1);  // 8x8x8 cells of side 0.5
  const mesh::CellComplex& m = *h.fine;
  const ElementSet e = ClassifyElements(m);
  EXPECT_EQ(e.num_cubic(), 6 * 6 * 6);
  const Points& p = m.positions();
  int exact = 0;
  for (int32_t el = 0; el < e.num_cubic(); ++el) {
    const int32_t* n = &e.cubic_nodes[64 * el];
    std::set<int32_t> distinct(n, n + 64);
    ASSERT_EQ(distinct.size(), 64u) << "element " << el;
    auto id = [&](int i, int j, int k) { return n[16 * i + 4 * j + k]; };
    auto at = [&](int i, int j, int k) -> Eigen::Vector3d { return p.row(id(i, j, k)); };
    // Topology: tensor neighbours along each axis are joined by an edge.
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) {
        for (int k = 0; k < 4; ++k) {
          if (i < 3) {
            ASSERT_GE(m.FindEdge(id(i, j, k), id(i + 1, j, k)), 0) << "u edge";
          }
          if (j < 3) {
            ASSERT_GE(m.FindEdge(id(i, j, k), id(i, j + 1, k)), 0) << "v edge";
          }
          if (k < 3) {
            ASSERT_GE(m.FindEdge(id(i, j, k), id(i, j, k + 1)), 0) << "w edge";
          }
        }
      }
    }
    // The cell's own corners are the nodes with indices 1..2.
    const auto cv = m.cell_vertices(e.cubic_cell[el]);
    for (int i = 1; i <= 2; ++i)
      for (int j = 1; j <= 2; ++j)
        for (int k = 1; k <= 2; ++k) EXPECT_TRUE(std::binary_search(cv.begin(), cv.end(), id(i, j, k)));
    const Eigen::Vector3d o = at(1, 1, 1);
    const Eigen::Vector3d du = at(2, 1, 1) - o, dv = at(1, 2, 1) - o, dw = at(1, 1, 2) - o;
    EXPECT_GT(du.dot(dv.cross(dw)), 0.0) << "element " << el << " frame is right-handed";
    // Where every node comes from interior rules (coordinates in [1, 3]),
    // fine points are the dyadic grid: node = o + (i-1) du + (j-1) dv + (k-1) dw.
    bool interior = true;
    for (int q = 0; q < 64; ++q) {
      interior &= p.row(n[q]).minCoeff() > 1.0 - 1e-9 && p.row(n[q]).maxCoeff() < 3.0 + 1e-9;
    }
    if (!interior) continue;
    ++exact;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k) {
          const Eigen::Vector3d want = o + (i - 1) * du + (j - 1) * dv + (k - 1) * dw;
          ASSERT_NEAR((at(i, j, k) - want).norm(), 0.0, 1e-12)
              << "element " << el << " node (" << i << "," << j << "," << k << ")";
        }
  }
  EXPECT_EQ(exact, 8);
}

TEST(ElementSetTest, LinearHexahedraArePositivelyOriented) {
  const auto h = Refine(Grid(2, 1, 1), 1);
  const ElementSet e = ClassifyElements(*h.fine);
  EXPECT_EQ(e.num_cubic(), 0);
  ASSERT_EQ(e.num_linear(), 16);
  const Points& p = h.fine->positions();
  for (int32_t el = 0; el < e.num_linear(); ++el) {
    const int32_t* n = &e.linear_nodes[8 * el];
    const Eigen::Vector3d o = p.row(n[0]);
    const Eigen::Vector3d du = p.row(n[1]).transpose() - o;
    const Eigen::Vector3d dv = p.row(n[3]).transpose() - o;
    const Eigen::Vector3d dw = p.row(n[4]).transpose() - o;
    EXPECT_GT(du.dot(dv.cross(dw)), 0.0) << "linear element " << el;
  }
}

TEST(ElementSetTest, PyramidCellGetsVirtualNodeAndEightPyramids) {
  const auto h = Refine(::dynsolid::testing::Pyramid(), 1);
  const ElementSet e = ClassifyElements(*h.fine);
  EXPECT_EQ(e.num_linear(), 4);
  EXPECT_EQ(e.num_virtual_nodes, 1);
  EXPECT_EQ(e.num_pyramid(), 8);
  const auto n = NodeMatrix(*h.fine, h.a, e);
  ASSERT_EQ(n.rows(), h.fine->num_vertices() + 1);
  const Points d = n * h.control->positions();
  const Eigen::Vector3d centroid = h.fine->CellCentroid(e.virtual_node_cell[0]);
  EXPECT_NEAR((d.row(d.rows() - 1).transpose() - centroid).norm(), 0.0, 1e-12);
  // A's rows as they are; the virtual node's row the mean of its cell's
  // vertices' rows (against a dense sum), summing to one.
  const Eigen::MatrixXd dense_n(n), dense_a(h.a);
  EXPECT_EQ(dense_n.topRows(dense_a.rows()), dense_a);
  const auto verts = h.fine->cell_vertices(e.virtual_node_cell[0]);
  Eigen::RowVectorXd mean = Eigen::RowVectorXd::Zero(dense_a.cols());
  for (int32_t v : verts) mean += dense_a.row(v);
  mean /= static_cast<double>(verts.size());
  EXPECT_LT((dense_n.row(dense_n.rows() - 1) - mean).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_NEAR(dense_n.row(dense_n.rows() - 1).sum(), 1.0, 1e-14);
  // Each pyramid has positive volume: base normal points at the apex.
  for (int32_t el = 0; el < e.num_pyramid(); ++el) {
    const int32_t* q = &e.pyramid_nodes[5 * el];
    const Eigen::Vector3d a = d.row(q[0]), b = d.row(q[1]), c = d.row(q[2]), x = d.row(q[4]);
    const Eigen::Vector3d nrm = (b - a).cross(c - a);
    EXPECT_GT(nrm.dot(x - a), 0.0) << "pyramid " << el;
  }
}

TEST(ElementSetTest, LevelZeroTetrahedronIsFourDegeneratePyramids) {
  const auto h = Refine(::dynsolid::testing::Tetrahedron(), 0);
  const ElementSet e = ClassifyElements(*h.fine);
  EXPECT_EQ(e.num_virtual_nodes, 1);
  EXPECT_EQ(e.num_pyramid(), 4);
}

}  // namespace
}  // namespace dynsolid::fem
