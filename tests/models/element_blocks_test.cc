// The element layout's relabelling of element axes (AlignElementAxes in
// element_blocks.cc): each cubic and linear element keeps its nodes and
// its geometry, congruent elements of a block fall into one group whatever
// orientation the mesh gave their cells, and batches of a group are
// compact clusters.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "solver/common/worker_pool.h"
#include "solver/fem/element_data.h"
#include "tests/models/model_fixture.h"

namespace dynsolid::models {
namespace {

// The physical points of an element's quadrature rule (node rows `ids` of
// `rest` under the kind's shape functions) and the smallest
// Jacobian determinant over them.
struct ElementGeometry {
  std::vector<std::array<double, 3>> points;
  double min_det = 0;
};
ElementGeometry Geometry(const fem::KindTable& table, const int32_t* ids, const Points& rest) {
  const int n = table.nodes;
  fem::NodeMatrixX3 x(n, 3), g;
  for (int i = 0; i < n; ++i) x.row(i) = rest.row(ids[i]);
  ElementGeometry out;
  out.min_det = std::numeric_limits<double>::infinity();
  for (int q = 0; q < table.points; ++q) {
    const Eigen::Map<const Eigen::Matrix<double, 1, Eigen::Dynamic>> nq(table.N(q), n);
    const Eigen::RowVector3d p = nq * x;
    out.points.push_back({p[0], p[1], p[2]});
    out.min_det = std::min(out.min_det, fem::PhysicalGradients(table.dN(q), x, n, g));
  }
  return out;
}

const std::vector<int32_t>& SetNodes(const fem::ElementSet& e, int kind) {
  return kind == 0 ? e.cubic_nodes : e.linear_nodes;
}

class AlignedAxesTest : public ::testing::TestWithParam<std::string> {};

// Every cubic and linear element of the layout has the element set's nodes
// (as a set), its quadrature points at the same physical places (as a
// set), and a rest Jacobian of the same sign: the relabelled element is the
// same element.
TEST_P(AlignedAxesTest, ElementsKeepTheirNodesAndGeometry) {
  test_util::MeshFixture f;
  test_util::BuildMesh(scene::BuiltinScene(GetParam()), 2, test_util::TwoMaterials(1e5, 0.3), f);
  int64_t relabelled = 0, checked = 0;
  for (int kind = 0; kind < 2; ++kind) {
    const ElementBlock& block = f.layout.blocks[kind];
    const fem::KindTable& table = f.layout.tables[kind];
    const int n = block.nodes;
    const std::vector<int32_t>& original = SetNodes(f.d.elements, kind);
    ASSERT_EQ(original.size(), block.node_ids.size());
    const double size = (f.rest.colwise().maxCoeff() - f.rest.colwise().minCoeff()).maxCoeff();
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* now = block.element_nodes(e);
      const int32_t* before = original.data() + static_cast<size_t>(e) * n;
      std::vector<int32_t> a(now, now + n), b(before, before + n);
      relabelled += a != b ? 1 : 0;
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      ASSERT_EQ(a, b) << GetParam() << " kind " << kind << " element " << e;
      const ElementGeometry gn = Geometry(table, now, f.rest);
      const ElementGeometry gb = Geometry(table, before, f.rest);
      ASSERT_EQ(gn.min_det > 0, gb.min_det > 0) << GetParam() << " kind " << kind << " element " << e;
      EXPECT_NEAR(gn.min_det, gb.min_det, 1e-9 * std::abs(gb.min_det) + 1e-300);
      // The same points up to rounding: each one's nearest in the other set.
      for (const auto& p : gn.points) {
        double nearest = std::numeric_limits<double>::infinity();
        for (const auto& r : gb.points) {
          nearest = std::min(nearest, std::hypot(p[0] - r[0], p[1] - r[1], p[2] - r[2]));
        }
        ASSERT_LE(nearest, 1e-12 * size) << GetParam() << " kind " << kind << " element " << e;
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
  // The subdivided meshes hand over cells in mixed orientations: the
  // relabelling is not a no-op on any of these scenes.
  EXPECT_GT(relabelled, 0) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(Scenes, AlignedAxesTest,
                         ::testing::Values("block3", "chair", "torus", "mixed"));

// A uniform block: every cubic element is congruent, and so is every
// linear one (the boundary layer), so each kind is one group, also when the
// block is turned by an arbitrary rotation (all cells are turned alike, and
// matched to x, y, z alike). Batches of 64 consecutive cubic elements of
// the group are compact clusters: on the axis-aligned block they touch
// 7 x 7 x 7 = 343 nodes (a 4 x 4 x 4 cube of cells) or a few more where
// the curve wraps around the block's edges; on the turned block, whose
// Z-order curve runs along the turned axes, under twice that. (With the
// orientations the mesh hands over, a group is one element in every few
// cells and a batch touches some 1500-2000 nodes.)
TEST(AlignedAxes, UniformBlockIsOneGroupOfCompactBatches) {
  test_util::MeshFixture f;
  const MaterialSampler uniform = [](const Eigen::Vector3d&, int32_t) {
    return MaterialPoint{1e5, 0.3, 1000, 0};
  };
  test_util::BuildMesh(scene::BuiltinScene("block4"), 2, uniform, f);
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
  const Points turned = f.rest * turn.transpose();
  const ElementLayout turned_layout =
      BuildElementLayout(f.d.elements, turned, f.d.hierarchy.control_cell, uniform);
  const int32_t cluster = 7 * 7 * 7;
  for (const auto& [layout, limit] :
       {std::pair<const ElementLayout*, double>{&f.layout, 1.2 * cluster},
        std::pair<const ElementLayout*, double>{&turned_layout, 2.0 * cluster}}) {
    ASSERT_GT(layout->blocks[0].size(), 0);
    EXPECT_EQ(layout->blocks[0].groups.size(), 1u);
    EXPECT_EQ(layout->blocks[1].groups.size(), 1u);
    ElementSchedule schedule =
        ScheduleElements(*layout, 64, 8, static_cast<int32_t>(f.rest.rows()));
    IndexBatchNodes(*layout, schedule);
    int64_t nodes = 0, batches = 0, smallest = 1 << 30;
    for (const ElementBatch& b : schedule.batches) {
      if (b.kind != 0 || b.count != 64) continue;
      nodes += b.num_nodes;
      smallest = std::min<int64_t>(smallest, b.num_nodes);
      ++batches;
    }
    ASSERT_GT(batches, 0);
    EXPECT_LE(static_cast<double>(nodes) / batches, limit);
    if (layout == &f.layout) {
      EXPECT_EQ(smallest, cluster);
    }
  }
}


// RelayoutMaterials gives the layout BuildElementLayout gives for the same
// samples, bit for bit: material arrays, shapes and groups numbered alike,
// the same group data, element order and rest volume. Built here from a
// layout of two materials, with some elements given a third (a band, as a
// brush leaves) and some given back the first (an array the layout already
// has), on meshes with one shape (block3), many (chair) and all three kinds
// (mixed).
class RelayoutTest : public ::testing::TestWithParam<const char*> {};

void ExpectSameLayout(const ElementLayout& a, const ElementLayout& b) {
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (size_t k = 0; k < a.materials.size(); ++k) EXPECT_EQ(a.materials[k], b.materials[k]) << k;
  EXPECT_EQ(a.rest_volume, b.rest_volume);
  EXPECT_EQ(a.inverted_elements, b.inverted_elements);
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& x = a.blocks[kind];
    const ElementBlock& y = b.blocks[kind];
    EXPECT_EQ(x.node_ids, y.node_ids);
    EXPECT_EQ(x.cell, y.cell);
    EXPECT_EQ(x.group, y.group) << "kind " << kind;
    EXPECT_EQ(x.by_group, y.by_group);
    EXPECT_EQ(x.group_start, y.group_start);
    ASSERT_EQ(x.groups.size(), y.groups.size());
    for (size_t g = 0; g < x.groups.size(); ++g) {
      EXPECT_EQ(x.groups[g].representative, y.groups[g].representative);
      EXPECT_EQ(x.groups[g].material, y.groups[g].material);
      EXPECT_EQ(x.groups[g].rest, y.groups[g].rest);
      EXPECT_EQ(x.groups[g].centre_gradient, y.groups[g].centre_gradient);
      EXPECT_EQ(x.groups[g].shape_volume, y.groups[g].shape_volume);
      EXPECT_EQ(x.groups[g].shape_inverted, y.groups[g].shape_inverted);
      EXPECT_EQ(x.groups[g].centre_det, y.groups[g].centre_det);
      EXPECT_EQ(x.groups[g].rest_key, y.groups[g].rest_key);
    }
  }
}

TEST_P(RelayoutTest, EqualsTheLayoutBuiltFromTheSameSamples) {
  test_util::MeshFixture f;
  test_util::BuildMesh(scene::BuiltinScene(GetParam()), 2, test_util::TwoMaterials(1e5, 0.3), f);
  // The band: samples with 0.2 < y < 0.6 get Young's modulus 3e5 (a third
  // material), elements of cell 0 get 1e5 everywhere (the first's samples).
  auto painted = [](const Eigen::Vector3d& x, int32_t cell, const MaterialPoint& was) {
    MaterialPoint m = was;
    if (x.y() > 0.2 && x.y() < 0.6) m.young = 3e5;
    if (cell == 0) m.young = 1e5;
    return m;
  };
  const MaterialSampler two = test_util::TwoMaterials(1e5, 0.3);
  const MaterialSampler full = [&](const Eigen::Vector3d& x, int32_t cell) {
    return painted(x, cell, two(x, cell));
  };
  const ElementLayout built =
      BuildElementLayout(f.d.elements, f.rest, f.d.hierarchy.control_cell, full);
  std::vector<std::vector<MaterialPoint>> arrays;
  std::array<std::vector<int32_t>, 3> index;
  int32_t given = 0;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& block = f.layout.blocks[kind];
    const fem::KindTable& table = f.layout.tables[kind];
    index[kind].assign(block.size(), -1);
    fem::NodeMatrixX3 x(block.nodes, 3);
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < block.nodes; ++i) x.row(i) = f.rest.row(ids[i]);
      const int32_t cell = f.d.hierarchy.control_cell[block.cell[e]];
      std::vector<MaterialPoint> now = f.layout.materials[block.groups[block.group[e]].material];
      bool changed = false;
      for (int q = 0; q < table.points; ++q) {
        const MaterialPoint m = painted(SamplePosition(table, q, x), cell, now[q]);
        changed |= !(m == now[q]);
        now[q] = m;
      }
      if (changed) {
        index[kind][e] = static_cast<int32_t>(arrays.size());
        arrays.push_back(std::move(now));
        ++given;
      }
    }
  }
  ASSERT_GT(given, 0);
  const ElementLayout relaid = RelayoutMaterials(
      f.layout, f.rest, [&](int kind, int32_t e) -> const std::vector<MaterialPoint>* {
        return index[kind][e] < 0 ? nullptr : &arrays[index[kind][e]];
      });
  ExpectSameLayout(relaid, built);
  // And back: every element given its samples in the first layout.
  const ElementLayout back = RelayoutMaterials(
      relaid, f.rest, [&](int kind, int32_t e) {
        const ElementBlock& block = f.layout.blocks[kind];
        return &f.layout.materials[block.groups[block.group[e]].material];
      });
  ExpectSameLayout(back, f.layout);
}

INSTANTIATE_TEST_SUITE_P(Scenes, RelayoutTest, ::testing::Values("block3", "chair", "mixed"));

// A layout built with threads and with an earlier layout's shapes to take
// (one of other materials over the same rest nodes: every shape known, the
// groups different) is the layout built alone, bit for bit.
TEST_P(RelayoutTest, ThreadsAndAnEarlierLayoutsShapesChangeNothing) {
  test_util::MeshFixture f;
  test_util::BuildMesh(scene::BuiltinScene(GetParam()), 2, test_util::TwoMaterials(1e5, 0.3), f);
  const MaterialSampler one = [](const Eigen::Vector3d&, int32_t) {
    return MaterialPoint{2e5, 0.25, 900, 0};
  };
  const ElementLayout earlier =
      BuildElementLayout(f.d.elements, f.rest, f.d.hierarchy.control_cell, one);
  ASSERT_NE(earlier.materials[0], f.layout.materials[0]);
  WorkerPool pool(2);
  const ElementLayout built =
      BuildElementLayout(f.d.elements, f.rest, f.d.hierarchy.control_cell,
                         test_util::TwoMaterials(1e5, 0.3), nullptr, &earlier, &pool);
  ExpectSameLayout(built, f.layout);
}

}  // namespace
}  // namespace dynsolid::models
