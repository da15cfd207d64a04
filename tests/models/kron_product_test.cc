// Sum factorization of cubic element matrices (kron_product.h).
#include "solver/models/kron_product.h"

#include <random>
#include <string>

#include <gtest/gtest.h>

#include "solver/fem/quadrature.h"
#include "solver/fem/shape.h"
#include "solver/models/local_frame.h"
#include "tests/models/model_fixture.h"

namespace dynsolid::models {
namespace {

KroneckerBasis CubicBasis() {
  const fem::Rule1d rule = fem::GaussLegendre(fem::QuadratureOrder(fem::ElementKind::kCubic));
  return KroneckerBasis::Make(rule.points, rule.weights);
}

// K_a = sum_d c_ad T_d with c from a box of sides (hx, hy, hz) and Lame
// constants (lambda, mu) (the local-frame matrices' form).
std::array<Eigen::MatrixXd, 3> BoxMatrices(const KroneckerBasis& b, double hx, double hy,
                                           double hz, double lambda, double mu) {
  const double h[3] = {hx, hy, hz};
  const double vol = hx * hy * hz;
  std::array<Eigen::MatrixXd, 3> k;
  for (int a = 0; a < 3; ++a) {
    k[a] = Eigen::MatrixXd::Zero(64, 64);
    for (int d = 0; d < 3; ++d) {
      const double c = (d == a ? lambda + 2 * mu : mu) * vol / (h[d] * h[d]);
      k[a] += c * b.t[d];
    }
  }
  return k;
}

Eigen::MatrixXf RandomColumns(int count, unsigned seed) {
  std::mt19937 gen(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  Eigen::MatrixXf x(64, count);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = u(gen);
  return x;
}

TEST(KroneckerTest, FitRecoversTheBoxCoefficientsAndAppliesTheMatrix) {
  const KroneckerBasis basis = CubicBasis();
  const auto k = BoxMatrices(basis, 0.25, 0.5, 0.125, 2e5, 1e5);
  const auto fit = KroneckerStiffness::Fit(basis, k);
  ASSERT_TRUE(fit.has_value());
  // c_xx = (lambda + 2 mu) hy hz / hx.
  EXPECT_NEAR(fit->coefficient(0, 0), 4e5 * 0.5 * 0.125 / 0.25, 1e-6);
  const int count = 37;  // not a multiple of anything
  const Eigen::MatrixXf x = RandomColumns(count, 7);
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE((fit->Dense(basis, a) - k[a]).cwiseAbs().maxCoeff(),
              1e-12 * k[a].cwiseAbs().maxCoeff());
    const Eigen::MatrixXd want = k[a] * x.cast<double>();
    Eigen::MatrixXd y(64, count), yp(64, count);
    fit->Apply(a, x.data(), 64, count, y.data());
    fit->ApplyPortable(a, x.data(), 64, count, yp.data());
    const double scale = want.cwiseAbs().maxCoeff();
    EXPECT_LE((y - want).cwiseAbs().maxCoeff(), 2e-6 * scale) << "axis " << a;
    EXPECT_LE((yp - want).cwiseAbs().maxCoeff(), 2e-6 * scale) << "axis " << a;
  }
}

TEST(KroneckerTest, MatricesOfAnotherFormKeepTheDenseProduct) {
  const KroneckerBasis basis = CubicBasis();
  auto k = BoxMatrices(basis, 0.25, 0.25, 0.25, 2e5, 1e5);
  ASSERT_TRUE(KroneckerStiffness::Fit(basis, k).has_value());
  // A symmetric perturbation of 1e-8 of the largest entry (a slightly
  // sheared element, a graded material): no longer a sum of the three.
  const double scale = k[1].cwiseAbs().maxCoeff();
  k[1](3, 40) += 1e-8 * scale;
  k[1](40, 3) += 1e-8 * scale;
  EXPECT_FALSE(KroneckerStiffness::Fit(basis, k).has_value());
  // Not 64 x 64.
  std::array<Eigen::MatrixXd, 3> small = {Eigen::MatrixXd::Identity(8, 8),
                                          Eigen::MatrixXd::Identity(8, 8),
                                          Eigen::MatrixXd::Identity(8, 8)};
  EXPECT_FALSE(KroneckerStiffness::Fit(basis, small).has_value());
}

// block3 in one material: its interior cubic elements are unit-spaced
// boxes, so their group runs factorized, and the forces stay within the
// float products' rounding of the double model's.
TEST(KroneckerTest, Block3InteriorRunsFactorizedWithinRoundingOfDoubleProducts) {
  test_util::MeshFixture f;
  test_util::BuildMesh(scene::BuiltinScene("block3"), 2,
                       [](const Eigen::Vector3d&, int32_t) {
                         return MaterialPoint{1e5, 0.3, 1000, 0};
                       },
                       f);
  WorkerPool pool(2);
  const int32_t nodes = f.d.elements.num_nodes();
  LocalFrameModel dbl(f.layout, DeformationMeasure(f.d.fine(), f.d.elements, f.rest, kForceParts),
                      nodes, pool, nullptr, /*float_products=*/false);
  LocalFrameModel flt(f.layout, DeformationMeasure(f.d.fine(), f.d.elements, f.rest, kForceParts),
                      nodes, pool, nullptr, /*float_products=*/true);
  EXPECT_EQ(dbl.factorized_groups(), 0) << "double products stay dense";
  EXPECT_GE(flt.factorized_groups(), 1);
  // The 10^3 interior cubic elements of the 12^3 block are unit boxes.
  EXPECT_GE(flt.factorized_elements(), 512);
  Points d = f.rest;
  for (int64_t i = 0; i < d.rows(); ++i) {
    d(i, 0) += 0.02 * std::sin(1.0 + 2.0 * i);
    d(i, 1) -= 0.01 * std::cos(0.5 + i);
    d(i, 2) += 0.015 * std::cos(3.0 * i);
  }
  d = d * Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix().transpose();
  Points gd, gf;
  const double ed = dbl.Forces(d, gd);
  const double ef = flt.Forces(d, gf);
  const double scale = gd.cwiseAbs().maxCoeff();
  ASSERT_GT(scale, 0);
  EXPECT_LE((gf - gd).cwiseAbs().maxCoeff(), 1e-6 * scale);
  EXPECT_NEAR(ef, ed, 1e-6 * ed);
}

// Every scene's factorized groups apply their own matrices: the product
// against the group's dense double matrix on random columns.
TEST(KroneckerTest, EveryFactorizedGroupAppliesItsOwnMatrix) {
  for (const char* name : {"chair", "bridge", "torus", "nozzle", "block4"}) {
    test_util::MeshFixture f;
    test_util::BuildMesh(scene::BuiltinScene(name), 2,
                         [](const Eigen::Vector3d&, int32_t) {
                           return MaterialPoint{1e5, 0.3, 1000, 0};
                         },
                         f);
    WorkerPool pool(1);
    LocalFrameModel flt(f.layout,
                        DeformationMeasure(f.d.fine(), f.d.elements, f.rest, kForceParts),
                        f.d.elements.num_nodes(), pool, nullptr, /*float_products=*/true);
    LocalFrameModel dbl(f.layout,
                        DeformationMeasure(f.d.fine(), f.d.elements, f.rest, kForceParts),
                        f.d.elements.num_nodes(), pool, nullptr, /*float_products=*/false);
    const auto& groups = f.layout.blocks[0].groups;
    const fem::Rule1d rule =
        fem::GaussLegendre(fem::QuadratureOrder(fem::ElementKind::kCubic));
    const KroneckerBasis basis = KroneckerBasis::Make(rule.points, rule.weights);
    int fitted = 0;
    for (size_t g = 0; g < groups.size(); ++g) {
      const std::array<Eigen::MatrixXd, 3> k = {dbl.K(0, static_cast<int32_t>(g), 0),
                                                dbl.K(0, static_cast<int32_t>(g), 1),
                                                dbl.K(0, static_cast<int32_t>(g), 2)};
      const auto fit = KroneckerStiffness::Fit(basis, k);
      if (!fit) continue;
      ++fitted;
      const Eigen::MatrixXf x = RandomColumns(64, 11 + static_cast<unsigned>(g));
      for (int a = 0; a < 3; ++a) {
        const Eigen::MatrixXd want = k[a] * x.cast<double>();
        Eigen::MatrixXd y(64, 64);
        fit->Apply(a, x.data(), 64, 64, y.data());
        EXPECT_LE((y - want).cwiseAbs().maxCoeff(), 2e-6 * want.cwiseAbs().maxCoeff())
            << name << " group " << g << " axis " << a;
      }
    }
    // The model factorizes exactly the groups that fit; the box-built
    // scenes have some (their cubic elements are axis-aligned boxes), the
    // torus and the nozzle (curved) none.
    EXPECT_EQ(fitted, flt.factorized_groups()) << name;
    const std::string n(name);
    if (n == "chair" || n == "bridge" || n == "block4") {
      EXPECT_GT(fitted, 0) << name;
    } else {
      EXPECT_EQ(fitted, 0) << name;
    }
  }
}

}  // namespace
}  // namespace dynsolid::models
