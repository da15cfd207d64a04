// The corotational model's folded evaluation for backward Euler
// (UpdateFrames + AffineForces): with the frames held the force is affine in
// the positions, so g_R(x + h v) = g(x) + h K_R v and E_R(x + h v) =
// E(x) + h v . g(x) + h^2/2 v . K_R v, to rounding; UpdateFrames then
// AffineForces at the same state is Forces bit for bit; results do not
// depend on the thread count.
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "solver/models/corotational.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "tests/models/model_fixture.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::models {
namespace {

struct Fixture : test_util::MeshFixture {
  std::unique_ptr<WorkerPool> pool;
  std::unique_ptr<CorotationalModel> model;
};

std::unique_ptr<Fixture> Build(const char* name, int levels, int threads) {
  auto f = std::make_unique<Fixture>();
  // Two materials, so that groups differ by material too.
  test_util::BuildMesh(scene::BuiltinScene(name), levels, test_util::TwoMaterials(1e5, 0.3), *f);
  f->pool = std::make_unique<WorkerPool>(threads);
  f->model = std::make_unique<CorotationalModel>(f->layout, f->rest, *f->pool);
  return f;
}

// A smooth deformation (strains of about `amplitude`), turned by `angle` rad.
Points Deformed(const Points& rest, double amplitude, double angle) {
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(angle, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  Points p = rest;
  for (int64_t i = 0; i < p.rows(); ++i) {
    const double x = rest(i, 0), y = rest(i, 1), z = rest(i, 2);
    p(i, 0) += amplitude * std::sin(1.3 * x + 0.4 * y);
    p(i, 1) += amplitude * std::cos(0.7 * y - 0.9 * z + 0.3 * x);
    p(i, 2) += amplitude * (std::sin(z + 0.6 * x) + 0.4 * x * y);
  }
  return (p * r.transpose()).rowwise() + Eigen::RowVector3d(0.3, 1.2, -0.7);
}

using test_util::Dot;
using test_util::RandomPoints;

TEST(CorotationalFoldTest, UpdateFramesThenAffineForcesIsForcesBitForBit) {
  auto a = Build("mixed", 2, 2);
  auto b = Build("mixed", 2, 2);
  Points ga, gb;
  // A sequence of states, so the warm-started frames move as in a run.
  for (int k = 0; k < 4; ++k) {
    const Points d = Deformed(a->rest, 0.01 * (k + 1), 0.3 * k);
    const double ea = a->model->Forces(d, ga);
    b->model->UpdateFrames(d);
    const double eb = b->model->AffineForces(d, gb);
    EXPECT_EQ(ea, eb) << "state " << k;
    EXPECT_TRUE(ga == gb) << "state " << k;
    for (int kind = 0; kind < fem::kElementKinds; ++kind) {
      const auto fa = a->model->frames()[kind];
      const auto fb = b->model->frames()[kind];
      ASSERT_EQ(fa.size(), fb.size());
      for (size_t e = 0; e < fa.size(); ++e) {
        ASSERT_TRUE(fa[e].coeffs() == fb[e].coeffs()) << "state " << k << " kind " << kind
                                                      << " element " << e;
      }
    }
  }
}

TEST(CorotationalFoldTest, AffineForcesAheadIsForcesPlusTheLinearizedStep) {
  auto f = Build("mixed", 2, 2);
  const Points x = Deformed(f->rest, 0.03, 0.8);
  const Points v = RandomPoints(x.rows(), 5);
  // A large step (h |v| a tenth of the solid): the identity is exact, so
  // only rounding separates the two sides.
  const double h = 0.1 * 3.0 / v.cwiseAbs().maxCoeff();
  Points g, kv, ahead;
  const double e = f->model->Forces(x, g);  // frames of x
  f->model->ApplyLinearized(v, kv);
  const Points x_ahead = x + h * v;
  const double e_ahead = f->model->AffineForces(x_ahead, ahead);
  const Points two_pass = g + h * kv;
  const double err = (ahead - two_pass).norm() / two_pass.norm();
  const double e_two_pass = e + h * Dot(v, g) + 0.5 * h * h * Dot(v, kv);
  const double e_err = std::abs(e_ahead - e_two_pass) / e_two_pass;
  std::printf("|g_R(x + h v) - (g(x) + h K_R v)| / |.| = %.2e; energy: %.2e\n", err, e_err);
  EXPECT_LT(err, 1e-12) << "folded force against the two-pass force";
  EXPECT_LT(e_err, 1e-12) << "E_R(x + h v) against E + h v.g + h^2/2 v.K_R v";
  // Differs from the force with the frames of x + h v (the step is large).
  Points g_own;
  f->model->Forces(x_ahead, g_own);
  EXPECT_GT((g_own - ahead).norm(), 1e-6 * ahead.norm());
}

TEST(CorotationalFoldTest, ResultsAreBitIdenticalForAnyPoolSize) {
  Points g1;
  double e1 = 0;
  std::array<std::vector<Eigen::Quaterniond>, 3> frames1;
  for (int threads : {1, 2, 3}) {
    auto f = Build("mixed", 2, threads);
    const Points d = Deformed(f->rest, 0.02, 0.5);
    const Points v = RandomPoints(d.rows(), 9);
    f->model->UpdateFrames(d);
    Points g;
    const double e = f->model->AffineForces(d + 1e-3 * v, g);
    if (threads == 1) {
      g1 = g;
      e1 = e;
      frames1 = f->model->frames();
      continue;
    }
    EXPECT_EQ(e, e1) << threads << " threads";
    EXPECT_TRUE(g == g1) << threads << " threads";
    for (int kind = 0; kind < fem::kElementKinds; ++kind) {
      for (size_t i = 0; i < frames1[kind].size(); ++i) {
        ASSERT_TRUE(f->model->frames()[kind][i].coeffs() == frames1[kind][i].coeffs())
            << threads << " threads";
      }
    }
  }
}

}  // namespace
}  // namespace dynsolid::models
