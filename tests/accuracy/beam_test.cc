// Accuracy against analytic answers (the problems of
// bench/reports/accuracy.md, at small sizes): a cantilever under a tip
// load against Timoshenko beam theory and a bar in tension against
// F L / (E A), both with the corotational model at 2 levels, solved
// statically (linear, about rest).
#include <cmath>

#include <Eigen/Geometry>

#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::solid {
namespace {

std::unique_ptr<Solid> Make(const std::string& text) {
  auto scene = scene::ParseScene(text, "test");
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, "", std::nullopt);
  EXPECT_OK(d);
  auto s = Solid::Create(*scene, *std::move(d));
  EXPECT_OK(s);
  return s.ok() ? *std::move(s) : nullptr;
}

// A beam along x: [0, L] x [-w/2, w/2]^2, fixed at x = 0, with a load
// spread over the end face by several point forces (sum F).
std::string BeamScene(double length, double width, int along, int across, double e, double nu,
                      const std::string& load_axis, double force) {
  std::string loads;
  const int k = 3;  // k x k points over the end face
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j < k; ++j) {
      const double y = width * (-0.4 + 0.8 * i / (k - 1)), z = width * (-0.4 + 0.8 * j / (k - 1));
      loads += absl::StrFormat(
          "point_forces { position { x: %.17g y: %.17g z: %.17g } force { %s: %.17g } } ",
          length * (1 - 1e-9), y, z, load_axis, force / (k * k));
    }
  }
  return absl::StrFormat(R"pb(
    mesh { beam { length: %g width: %g height: %g cells_along: %d cells_across: %d } }
    subdivision { levels: 2 }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: %g poisson_ratio: %g density: 1000 } }
    constraints { fixed { box { min { x: -1e-6 y: -1 z: -1 } max { x: 1e-6 y: 1 z: 1 } } } }
    loads { %s }
    traced { name: "tip" position { x: %.17g y: 0 z: 0 } }
    solver { model: COROTATIONAL }
  )pb", length, width, width, along, across, e, nu, loads, length * (1 - 1e-9));
}

TEST(AccuracyTest, CantileverTipDeflectionMatchesTimoshenko) {
  const double l = 1.0, w = 0.1, e = 1e6, nu = 0.3, f = -1.0;
  auto s = Make(BeamScene(l, w, 10, 2, e, nu, "z", f));
  ASSERT_NE(s, nullptr);
  auto p = s->SolveStaticLinear();
  ASSERT_OK(p);
  const double tip = s->TracedPositionsAt(*p)[0].z();
  const double inertia = w * w * w * w / 12.0, area = w * w, g = e / (2 * (1 + nu));
  const double kappa = 10 * (1 + nu) / (12 + 11 * nu);  // square section (Cowper)
  const double timoshenko = f * l * l * l / (3 * e * inertia) + f * l / (kappa * g * area);
  const double euler_bernoulli = f * l * l * l / (3 * e * inertia);
  std::printf("cantilever tip: %.6g m; Timoshenko %.6g m (%.2f %%), Euler-Bernoulli %.6g m\n",
              tip, timoshenko, 100 * (tip - timoshenko) / timoshenko, euler_bernoulli);
  RecordProperty("tip_error_percent", absl::StrFormat("%.3f", 100 * (tip - timoshenko) / timoshenko));
  EXPECT_NEAR(tip, timoshenko, 0.05 * std::abs(timoshenko));
}

TEST(AccuracyTest, BarInTensionMatchesFLOverEA) {
  // nu = 0 in a scene means the default 0.3; a tiny nu stands for zero
  // (with nu > 0 the clamp's restrained contraction stiffens the bar).
  const double l = 1.0, w = 0.1, e = 1e6, nu = 1e-9, f = 1.0;
  auto s = Make(BeamScene(l, w, 10, 2, e, nu, "x", f));
  ASSERT_NE(s, nullptr);
  auto p = s->SolveStaticLinear();
  ASSERT_OK(p);
  const double stretch = s->TracedPositionsAt(*p)[0].x() - l * (1 - 1e-9);
  const double analytic = f * l / (e * w * w);
  std::printf("bar end displacement: %.6g m; F L / (E A) = %.6g m (%.2f %%)\n", stretch, analytic,
              100 * (stretch - analytic) / analytic);
  EXPECT_NEAR(stretch, analytic, 0.02 * analytic);
}

// The control-space internal forces A^T g(A p) are the gradient of the
// strain energy (the frames' own variation is second order in the strain)
// at a rotated, slightly deformed state of the beam.
TEST(AccuracyTest, ControlForcesAreTheStrainEnergyGradient) {
  auto s = Make(BeamScene(1.0, 0.1, 10, 2, 1e6, 0.3, "z", 0.0));
  ASSERT_NE(s, nullptr);
  const Points rest = s->control_positions();
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  Points p(rest.rows(), 3), v(rest.rows(), 3);
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    Eigen::Vector3d x = rest.row(i).transpose();
    x.y() += 0.001 * std::sin(7.0 * x.x());  // ~1 % strain
    x.z() += 0.001 * x.x() * x.x();
    p.row(i) = (r * x).transpose();
    for (int c = 0; c < 3; ++c) v(i, c) = std::sin(1.0 + 3.0 * i + 5.0 * c);
  }
  const Points g = s->InternalControlForces(p);
  const double analytic = (g.array() * v.array()).sum();
  const double h = 1e-7;
  const double fd = (s->StrainEnergy(p + h * v) - s->StrainEnergy(p - h * v)) / (2 * h);
  std::printf("dE/dv: forces %.10e, finite difference %.10e (relative %.2e)\n", analytic, fd,
              std::abs(fd - analytic) / std::abs(analytic));
  EXPECT_NEAR(fd, analytic, 1e-3 * std::abs(analytic));
  // And a rigid rotation of the rest shape carries no force and no energy.
  Points q(rest.rows(), 3);
  for (Eigen::Index i = 0; i < rest.rows(); ++i) q.row(i) = (r * rest.row(i).transpose()).transpose();
  EXPECT_LT(s->InternalControlForces(q).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(std::abs(s->StrainEnergy(q)), 1e-12);
}

}  // namespace
}  // namespace dynsolid::solid
