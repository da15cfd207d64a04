// ExtractRotationNewton (rotation.h) against the polar decomposition from an
// SVD and against ExtractRotation run to convergence: the same rotation, from
// warm starts near it and from identity up to large rotations, with
// quadratic convergence (few iterations from a warm start).
#include "solver/models/rotation.h"

#include <cmath>
#include <random>

#include <Eigen/SVD>
#include <gtest/gtest.h>

namespace dynsolid::models {
namespace {

// The rotation of F's polar decomposition (det F > 0).
Eigen::Matrix3d Polar(const Eigen::Matrix3d& f) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

Eigen::Quaterniond RandomRotation(std::mt19937& rng, double max_angle) {
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::Vector3d axis(u(rng), u(rng), u(rng));
  return Eigen::Quaterniond(Eigen::AngleAxisd(max_angle * std::abs(u(rng)), axis.normalized()));
}

// F = R U, U symmetric positive definite with strains up to `strain`.
Eigen::Matrix3d RandomF(std::mt19937& rng, const Eigen::Matrix3d& r, double strain) {
  std::uniform_real_distribution<double> u(-strain, strain);
  Eigen::Matrix3d e;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) e(i, j) = u(rng);
  return r * (Eigen::Matrix3d::Identity() + 0.5 * (e + e.transpose()));
}

TEST(RotationTest, NewtonFindsThePolarRotationFromWarmAndColdStarts) {
  std::mt19937 rng(7);
  double worst = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    const Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), trial % 2 ? 0.3 : 0.01);
    const Eigen::Matrix3d polar = Polar(f);
    // Warm start 0.02 rad away; cold start from the rotation 1.1 rad away.
    for (double off : {0.02, 1.1}) {
      Eigen::Quaterniond q = truth * RandomRotation(rng, off);
      ExtractRotationNewton(f, q, 32);
      const double err = (q.toRotationMatrix() - polar).cwiseAbs().maxCoeff();
      worst = std::max(worst, err);
      ASSERT_LT(err, 1e-12) << "trial " << trial << " start " << off << " rad away";
      EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    }
  }
  std::printf("largest |R_newton - R_polar| = %.2e\n", worst);
}

TEST(RotationTest, NewtonAgreesWithTheLinearIterationAndConvergesQuadratically) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    const Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), 0.05);
    const Eigen::Quaterniond start = truth * RandomRotation(rng, 1e-3);
    Eigen::Quaterniond linear = start, newton3 = start;
    ExtractRotation(f, linear, 200);
    // Three Newton iterations from 1e-3 rad: 1e-3 -> ~1e-6 -> ~1e-12 -> rounding.
    ExtractRotationNewton(f, newton3, 3);
    EXPECT_LT((linear.toRotationMatrix() - newton3.toRotationMatrix()).cwiseAbs().maxCoeff(),
              5e-13)
        << "trial " << trial;
    // The linear iteration is not there after three.
    Eigen::Quaterniond linear3 = start;
    ExtractRotation(f, linear3, 3);
    EXPECT_GT((linear3.toRotationMatrix() - linear.toRotationMatrix()).cwiseAbs().maxCoeff(),
              1e-9)
        << "trial " << trial;
  }
}

TEST(RotationTest, NewtonGivesASymmetricStretchForInvertedAndDegenerateF) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), 0.2);
    if (trial % 2) f.col(trial % 3) *= -0.5;  // inverted
    else f.col(trial % 3).setZero();          // flat
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    ExtractRotationNewton(f, q, 32);
    ASSERT_TRUE(q.coeffs().allFinite()) << "trial " << trial;
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    // A fixed point: R^T F symmetric.
    const Eigen::Matrix3d s = q.toRotationMatrix().transpose() * f;
    EXPECT_LT((s - s.transpose()).cwiseAbs().maxCoeff(), 1e-12 * f.norm()) << "trial " << trial;
  }
}

}  // namespace
}  // namespace dynsolid::models
