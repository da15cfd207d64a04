// The cell partials of a build (cell_partials.h) against a reference
// summed element by element, point by point, from the element tables alone;
// and made in one pass (SumByCells, sharing CellPoints) with the same bits
// as made alone.
#include "solver/solid/cell_partials.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "solver/common/worker_pool.h"
#include "solver/fem/element_data.h"
#include "solver/models/corotational.h"
#include "tests/models/model_fixture.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

using models::MaterialPoint;

// Density 1000 everywhere; damping `c(x)`.
models::MaterialSampler Damped(double (*c)(const Eigen::Vector3d&)) {
  return [c](const Eigen::Vector3d& x, int32_t) { return MaterialPoint{1e5, 0.3, 1000, c(x)}; };
}

// A^T (sum_e sum_q value_q dV_q N_q^T N_q) A, dense, value the density
// (damping: false) or the damping at each point.
Eigen::MatrixXd Reference(const models::test_util::MeshFixture& f, bool damping) {
  const Eigen::MatrixXd a = Eigen::MatrixXd(f.d.node_matrix);
  Eigen::MatrixXd nodes = Eigen::MatrixXd::Zero(a.rows(), a.rows());
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = f.layout.blocks[kind];
    const fem::KindTable& table = f.layout.tables[kind];
    const int n = table.nodes;
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      fem::NodeMatrixX3 x(n, 3);
      for (int i = 0; i < n; ++i) x.row(i) = f.rest.row(ids[i]);
      const auto& material = f.layout.materials[block.groups[block.group[e]].material];
      for (int q = 0; q < table.points; ++q) {
        const double dv = std::max(fem::RestJacobian(table.dN(q), x, n).determinant(), 0.0) *
                          table.weight[q];
        const double value = (damping ? material[q].damping : material[q].density) * dv;
        for (int i = 0; i < n; ++i) {
          for (int j = 0; j < n; ++j) nodes(ids[i], ids[j]) += value * table.N(q)[i] * table.N(q)[j];
        }
      }
    }
  }
  return a.transpose() * nodes * a;
}

struct Sums {
  CellSums mass, stiffness;
};

// Mt (and Dt) dense, and the per-cell K0 partials: in one pass when
// `together`, else each sum alone.
Sums Build(const models::test_util::MeshFixture& f, bool together) {
  WorkerPool pool(2);
  const models::CorotationalModel corot(f.layout, f.rest, pool, nullptr, models::kEveryGroup,
                                        models::CorotationalModel::Products::kWhenUsed);
  bool damping = false;
  for (const auto& array : f.layout.materials) {
    for (const MaterialPoint& m : array) damping |= m.damping > 0;
  }
  Sums out;
  const auto& nm = f.d.node_matrix;
  const int32_t cells = f.d.control().num_cells();
  const auto& control_cell = f.d.hierarchy.control_cell;
  if (together) {
    CellPoints points(f.layout, nm, pool.size());
    StiffnessPartials stiffness(f.layout, corot, points, pool.size());
    MassPartials mass(f.layout, damping, points, pool.size());
    stiffness.spec().per_cell = true;
    std::vector<CellSumJob> jobs = {{&stiffness.spec(), nullptr, false, &out.stiffness, nullptr},
                                    {&mass.spec(), nullptr, true, &out.mass, nullptr}};
    SumByCells(nm, f.layout, control_cell, cells, jobs, pool);
    return out;
  }
  {
    CellPoints points(f.layout, nm, pool.size());
    StiffnessPartials stiffness(f.layout, corot, points, pool.size());
    stiffness.spec().per_cell = true;
    SumByCell(nm, f.layout, control_cell, cells, stiffness.spec(), nullptr, pool, false,
              out.stiffness);
  }
  CellPoints points(f.layout, nm, pool.size());
  MassPartials mass(f.layout, damping, points, pool.size());
  SumByCell(nm, f.layout, control_cell, cells, mass.spec(), nullptr, pool, true, out.mass);
  return out;
}

double RelativeError(const Eigen::MatrixXd& got, const Eigen::MatrixXd& want) {
  return (got - want).norm() / want.norm();
}

// Damping proportional to density everywhere (Dt's partials: the ratio
// times Mt's) and damping that varies through some cells (their own Gram
// matrices): both as the reference sums them.
TEST(CellPartialsTest, MassAndDampingEqualTheReferenceSum) {
  for (const bool proportional : {true, false}) {
    SCOPED_TRACE(proportional ? "damping 0.5 density" : "damping varying with x");
    models::test_util::MeshFixture f;
    models::test_util::BuildMesh(
        scene::BuiltinScene("block3"), 1,
        proportional ? Damped([](const Eigen::Vector3d&) { return 500.0; })
                     : Damped([](const Eigen::Vector3d& x) { return 400.0 + 300.0 * x.x() * x.x(); }),
        f);
    const Sums s = Build(f, true);
    ASSERT_EQ(s.mass.matrices.size(), 2u);
    EXPECT_LT(RelativeError(s.mass.matrices[0], Reference(f, false)), 1e-13);
    EXPECT_LT(RelativeError(s.mass.matrices[1], Reference(f, true)), 1e-13);
  }
}

// A locally refined block: the refined cell's neighbours are split where
// they meet it, and some cells' supports pass 64 control points (more than
// one word of CellPoints' column masks). Mt and Dt still equal the
// reference.
TEST(CellPartialsTest, SupportsOfMoreThanSixtyFourPointsSumAsTheReference) {
  absl::StatusOr<Scene> scene = scene::BuiltinScene("block3");
  ASSERT_OK(scene);
  scene->mutable_mesh()->add_refine_cells(13);  // the centre cell
  models::test_util::MeshFixture f;
  models::test_util::BuildMesh(
      scene, 1, Damped([](const Eigen::Vector3d& x) { return 400.0 + 300.0 * x.z(); }), f);
  const Sums s = Build(f, true);
  size_t widest = 0;
  for (const auto& support : s.stiffness.supports) widest = std::max(widest, support.size());
  EXPECT_GT(widest, 64u);
  ASSERT_EQ(s.mass.matrices.size(), 2u);
  EXPECT_LT(RelativeError(s.mass.matrices[0], Reference(f, false)), 1e-13);
  EXPECT_LT(RelativeError(s.mass.matrices[1], Reference(f, true)), 1e-13);
}

// Made in one pass, sharing what they read of each cell, the partials have
// the bits of each sum made alone (a thread's cell data is never stale).
TEST(CellPartialsTest, OnePassGivesTheBitsOfEachSumAlone) {
  models::test_util::MeshFixture f;
  models::test_util::BuildMesh(
      scene::BuiltinScene("block3"), 2,
      Damped([](const Eigen::Vector3d& x) { return x.y() > 0.4 ? 700.0 : 500.0; }), f);
  const Sums one = Build(f, true);
  const Sums alone = Build(f, false);
  ASSERT_EQ(one.mass.matrices.size(), 2u);
  for (int o = 0; o < 2; ++o) EXPECT_EQ(one.mass.matrices[o], alone.mass.matrices[o]) << o;
  ASSERT_EQ(one.stiffness.partials.size(), alone.stiffness.partials.size());
  ASSERT_GT(one.stiffness.partials.size(), 1u);
  for (size_t c = 0; c < one.stiffness.partials.size(); ++c) {
    EXPECT_EQ(one.stiffness.supports[c], alone.stiffness.supports[c]) << "cell " << c;
    for (int m = 0; m < 2; ++m) {
      EXPECT_EQ((*one.stiffness.partials[c])[m], (*alone.stiffness.partials[c])[m])
          << "cell " << c << " matrix " << m;
    }
  }
}

}  // namespace
}  // namespace dynsolid::solid
