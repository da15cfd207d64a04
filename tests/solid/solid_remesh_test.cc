// Carrying a solid's state over a new control mesh (solid.h Remeshed). The
// edits themselves are solver/sculpt's; here the "edit" is the identity
// (the same mesh given inline, every vertex its own source), so the solid
// carried over must go on exactly like the original.
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/inline_mesh.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::solid {
namespace {

using ::dynsolid::testing::Parse;

mesh::MeshInput ToInput(const mesh::CellComplex& c) {
  mesh::MeshInput m;
  m.vertices = c.positions();
  std::vector<int32_t> loop;
  for (int32_t cell = 0; cell < c.num_cells(); ++cell) {
    auto& faces = m.cells.emplace_back();
    for (size_t k = 0; k < c.cell_faces(cell).size(); ++k) {
      c.CellFaceLoop(cell, static_cast<int32_t>(k), loop);
      faces.push_back(loop);
    }
  }
  return m;
}

const char* kScene = R"pb(
  name: "remesh"
  mesh { block { nx: 2 ny: 2 nz: 2 } }
  subdivision { levels: 1 }
  materials { base { young_modulus: 1e4 density: 100 } }
  constraints { fixed { box { min { x: -1 y: -1 z: -0.01 } max { x: 3 y: 3 z: 0.01 } } } }
  traced { name: "top" position { x: 1 y: 1 z: 1.8 } }
  solver { time_step: 1e-3 }
)pb";

struct Built {
  Scene scene;
  std::unique_ptr<Solid> solid;
};

Built Make() {
  Built b;
  b.scene = *scene::ParseScene(kScene, "test");
  auto d = scene::BuildDiscretization(b.scene, "", std::nullopt);
  EXPECT_OK(d);
  auto s = Solid::Create(b.scene, *std::move(d));
  EXPECT_OK(s);
  b.solid = *std::move(s);
  return b;
}

TEST(SolidRemeshTest, AnIdentityTransferGoesOnLikeTheOriginal) {
  Built a = Make();
  Solid& s = *a.solid;
  // A live state: moving, a point force, a drag, a pin, a paint, gravity.
  ASSERT_OK(s.AddPointForce(Parse<PointForce>(
      "position { x: 1.5 y: 1 z: 1.7 } force { x: 30 y: 0 z: 0 }")));
  ASSERT_OK(s.AddDrag(Parse<Drag>(
      "material_point { x: 0.5 y: 1 z: 1.7 } target { x: 0.3 y: 1 z: 2.0 } stiffness: 5e3")));
  ASSERT_OK(s.FixRegion(Parse<Region>("box { min { x: 1.9 y: -1 z: 0.9 } max { x: 3 y: 3 z: 1.1 } }")));
  ASSERT_OK(s.PaintMaterial(Parse<MaterialPaint>(
      "region { sphere { center { x: 1 y: 1 z: 2 } radius: 0.8 } } material { young_modulus: 1e5 "
      "density: 300 } strength: 1")));
  ASSERT_OK(s.SetGravity(Parse<Vec3>("z: -9.81")));
  for (int i = 0; i < 30; ++i) ASSERT_OK(s.Step());

  // The same control mesh, inline.
  Scene edited = a.scene;
  const mesh::MeshInput input = ToInput(s.discretization().control());
  edited.mutable_mesh()->Clear();
  *edited.mutable_mesh()->mutable_inline_mesh() = scene::InlineFromMesh(input);
  ASSERT_OK_AND_ASSIGN(scene::Discretization d, scene::Discretize(edited, input, std::nullopt));
  Solid::TopologyTransfer t;
  t.current = s.control_positions();
  for (int32_t v = 0; v < t.current.rows(); ++v) t.vertex_sources.push_back({{v, 1.0}});
  for (int32_t c = 0; c < d.control().num_cells(); ++c) t.cell_source.push_back(c);
  Solid::TransferReport report;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solid> r, s.Remeshed(edited, std::move(d), t, &report));

  EXPECT_TRUE(report.dropped_loads.empty());
  EXPECT_TRUE(report.dropped_constraints.empty());
  EXPECT_TRUE(report.dropped_traced.empty());
  EXPECT_EQ(r->load_ids(), s.load_ids());
  EXPECT_EQ(r->constraint_ids(), s.constraint_ids());
  EXPECT_EQ(r->steps(), s.steps());
  EXPECT_EQ(r->time(), s.time());
  EXPECT_EQ(r->topology_version(), s.topology_version() + 1);
  EXPECT_NEAR(r->total_mass(), s.total_mass(), 1e-12 * s.total_mass());  // summed in another order
  EXPECT_EQ(r->gravity(), s.gravity());
  EXPECT_EQ(r->control_positions(), s.control_positions());
  EXPECT_EQ(r->TracedPositions(), s.TracedPositions());
  // The same energies (same velocities, materials, positions).
  const Energies e0 = s.ComputeEnergies(), e1 = r->ComputeEnergies();
  EXPECT_NEAR(e1.kinetic, e0.kinetic, 1e-9 * (1 + e0.kinetic));
  // And the same motion afterwards, to rounding of the velocity's round trip.
  for (int i = 0; i < 50; ++i) {
    ASSERT_OK(s.Step());
    ASSERT_OK(r->Step());
  }
  const double scale = s.control_positions().cwiseAbs().maxCoeff();
  EXPECT_LT((r->control_positions() - s.control_positions()).cwiseAbs().maxCoeff(), 1e-9 * scale);

  // The report's scene makes a solid that takes the new solid's states.
  ASSERT_OK_AND_ASSIGN(scene::Discretization d2,
                       scene::BuildDiscretization(report.scene, "", std::nullopt));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solid> again, Solid::Create(report.scene, std::move(d2)));
  ASSERT_OK(again->RestoreState(r->SaveState()));
  for (int i = 0; i < 10; ++i) {
    ASSERT_OK(again->Step());
    ASSERT_OK(r->Step());
  }
  EXPECT_EQ(again->SaveState(), r->SaveState());
}

TEST(SolidRemeshTest, ItemsWithoutAPlaceOnTheNewMeshAreDroppedAndNamed) {
  Built a = Make();
  Solid& s = *a.solid;
  ASSERT_OK_AND_ASSIGN(int64_t force, s.AddPointForce(Parse<PointForce>(
      "position { x: 1.5 y: 1.5 z: 1.5 } force { x: 30 y: 0 z: 0 }")));
  ASSERT_OK_AND_ASSIGN(int64_t fix, s.FixRegion(Parse<Region>("control_cells: 7")));
  ASSERT_OK_AND_ASSIGN(int64_t keep, s.AddPointForce(Parse<PointForce>(
      "position { x: 0.5 y: 0.5 z: 0.5 } force { x: 30 y: 0 z: 0 }")));
  for (int i = 0; i < 5; ++i) ASSERT_OK(s.Step());
  // Keep cells 0..6 of the 2x2x2 block (drop cell 7, the corner at (1..2)^3).
  const mesh::MeshInput full = ToInput(s.discretization().control());
  mesh::MeshInput input;
  input.cells.assign(full.cells.begin(), full.cells.begin() + 7);
  // Vertex 26 (the corner (2, 2, 2)) belongs to cell 7 only.
  std::vector<int32_t> map(full.vertices.rows(), -1);
  std::vector<int32_t> sources;
  for (auto& cell : input.cells) {
    for (auto& loop : cell) {
      for (int32_t& v : loop) {
        if (map[v] < 0) {
          map[v] = 0;
        }
      }
    }
  }
  int32_t next = 0;
  for (int32_t v = 0; v < full.vertices.rows(); ++v) {
    if (map[v] == 0) {
      map[v] = next++;
      sources.push_back(v);
    }
  }
  for (auto& cell : input.cells) {
    for (auto& loop : cell) {
      for (int32_t& v : loop) v = map[v];
    }
  }
  input.vertices.resize(next, 3);
  Solid::TopologyTransfer t;
  t.current.resize(next, 3);
  for (int32_t v = 0; v < next; ++v) {
    input.vertices.row(v) = full.vertices.row(sources[v]);
    t.current.row(v) = s.control_positions().row(sources[v]);
    t.vertex_sources.push_back({{sources[v], 1.0}});
  }
  EXPECT_EQ(next, 26);
  for (int32_t c = 0; c < 7; ++c) t.cell_source.push_back(c);
  Scene edited = a.scene;
  edited.mutable_mesh()->Clear();
  *edited.mutable_mesh()->mutable_inline_mesh() = scene::InlineFromMesh(input);
  ASSERT_OK_AND_ASSIGN(scene::Discretization d, scene::Discretize(edited, input, std::nullopt));
  Solid::TransferReport report;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solid> r, s.Remeshed(edited, std::move(d), t, &report));
  EXPECT_THAT(report.dropped_loads, ::testing::ElementsAre(force));
  EXPECT_THAT(report.dropped_constraints, ::testing::ElementsAre(fix));
  EXPECT_THAT(r->load_ids(), ::testing::ElementsAre(keep));
  EXPECT_EQ(r->constraint_ids().size(), s.constraint_ids().size() - 1);
  for (int i = 0; i < 200; ++i) ASSERT_OK(r->Step());
  EXPECT_EQ(r->rollbacks(), 0);
}

}  // namespace
}  // namespace dynsolid::solid
