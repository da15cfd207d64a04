// ExtractRotation (rotation.h) against the polar decomposition from an SVD
// and against the linear iteration (ExtractRotationLinear) run to
// convergence: the same rotation, from warm starts near it and from
// identity up to large rotations, with quadratic convergence (few
// iterations from a warm start), and a proper rotation for inverted or
// flat elements.
#include "solver/models/rotation.h"

#include <cmath>
#include <cstdio>
#include <random>

#include <Eigen/SVD>
#include <gtest/gtest.h>

namespace dynsolid::models {
namespace {

// The polar rotation of F (det F > 0) from its SVD.
Eigen::Matrix3d Polar(const Eigen::Matrix3d& f) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

Eigen::Matrix3d Rot(double angle, Eigen::Vector3d axis) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

// A stretch S (symmetric positive definite) turned by R: F = R S.
Eigen::Matrix3d Deformed(const Eigen::Matrix3d& r, const Eigen::Vector3d& stretches,
                         const Eigen::Matrix3d& axes) {
  return r * axes * stretches.asDiagonal() * axes.transpose();
}

TEST(ExtractRotationTest, NewtonConvergesFromAStepOldWarmStartInFewIterations) {
  const Eigen::Matrix3d axes = Rot(0.4, {1, 2, 3});
  const Eigen::Matrix3d r_true = Rot(0.7, {0.3, -1, 0.5});
  const Eigen::Matrix3d f = Deformed(r_true, {1.02, 0.99, 1.01}, axes);
  // Last step's frame: 1e-3 rad off.
  Eigen::Quaterniond q(Rot(1e-3, {1, 1, 0}).transpose() * r_true);
  Eigen::Matrix3d r;
  ExtractRotation(f, q, 4, &r);
  EXPECT_LT((r - Polar(f)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((q.toRotationMatrix() - r).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(ExtractRotationTest, LargeTurnsAndAnisotropicStretchReachThePolarRotation) {
  const Eigen::Matrix3d axes = Rot(1.1, {0, 1, 1});
  for (double angle : {0.5, 1.5, 3.0}) {
    for (const Eigen::Vector3d& s :
         {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(2, 0.5, 0.5), Eigen::Vector3d(0.3, 1.5, 4)}) {
      const Eigen::Matrix3d f = Deformed(Rot(angle, {1, -2, 0.5}), s, axes);
      Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
      Eigen::Matrix3d r;
      ExtractRotation(f, q, 200, &r);
      EXPECT_LT((r - Polar(f)).cwiseAbs().maxCoeff(), 1e-10)
          << "angle " << angle << " stretches " << s.transpose();
    }
  }
}

TEST(ExtractRotationTest, InvertedElementGivesAProperRotation) {
  Eigen::Matrix3d f = Rot(0.3, {0, 0, 1});
  f.col(2) *= -0.2;  // flattened through itself: det F < 0
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Matrix3d r;
  ExtractRotation(f, q, 50, &r);
  EXPECT_TRUE(r.allFinite());
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(ExtractRotationTest, ARotationIsItsOwnFrameAtOnce) {
  const Eigen::Matrix3d r_true = Rot(2.0, {1, 1, 1});
  Eigen::Quaterniond q(r_true);
  const Eigen::Quaterniond before = q;
  Eigen::Matrix3d r;
  ExtractRotation(r_true, q, 1, &r);
  EXPECT_EQ(q.coeffs(), before.coeffs()) << "nothing to turn";
  EXPECT_LT((r - r_true).cwiseAbs().maxCoeff(), 1e-15);
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

TEST(ExtractRotationTest, NewtonFindsThePolarRotationFromWarmAndColdStarts) {
  std::mt19937 rng(7);
  double worst = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    const Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), trial % 2 ? 0.3 : 0.01);
    const Eigen::Matrix3d polar = Polar(f);
    // Warm start 0.02 rad away; cold start from the rotation 1.1 rad away.
    for (double off : {0.02, 1.1}) {
      Eigen::Quaterniond q = truth * RandomRotation(rng, off);
      ExtractRotation(f, q, 32);
      const double err = (q.toRotationMatrix() - polar).cwiseAbs().maxCoeff();
      worst = std::max(worst, err);
      ASSERT_LT(err, 1e-12) << "trial " << trial << " start " << off << " rad away";
      EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    }
  }
  std::printf("largest |R_newton - R_polar| = %.2e\n", worst);
}

TEST(ExtractRotationTest, NewtonAgreesWithTheLinearIterationAndConvergesQuadratically) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    const Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), 0.05);
    const Eigen::Quaterniond start = truth * RandomRotation(rng, 1e-3);
    Eigen::Quaterniond linear = start, newton3 = start;
    ExtractRotationLinear(f, linear, 200);
    // Three Newton iterations from 1e-3 rad: 1e-3 -> ~1e-6 -> ~1e-12 -> rounding.
    ExtractRotation(f, newton3, 3);
    EXPECT_LT((linear.toRotationMatrix() - newton3.toRotationMatrix()).cwiseAbs().maxCoeff(),
              5e-13)
        << "trial " << trial;
    // The linear iteration is not there after three.
    Eigen::Quaterniond linear3 = start;
    ExtractRotationLinear(f, linear3, 3);
    EXPECT_GT((linear3.toRotationMatrix() - linear.toRotationMatrix()).cwiseAbs().maxCoeff(),
              1e-9)
        << "trial " << trial;
  }
}

TEST(ExtractRotationTest, NewtonGivesASymmetricStretchForInvertedAndDegenerateF) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond truth = RandomRotation(rng, M_PI);
    Eigen::Matrix3d f = RandomF(rng, truth.toRotationMatrix(), 0.2);
    if (trial % 2) f.col(trial % 3) *= -0.5;  // inverted
    else f.col(trial % 3).setZero();          // flat
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    ExtractRotation(f, q, 32);
    ASSERT_TRUE(q.coeffs().allFinite()) << "trial " << trial;
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    // A fixed point: R^T F symmetric.
    const Eigen::Matrix3d s = q.toRotationMatrix().transpose() * f;
    EXPECT_LT((s - s.transpose()).cwiseAbs().maxCoeff(), 1e-12 * f.norm()) << "trial " << trial;
  }
}

TEST(ExtractRotationTest, TurnByIsTheExactTurnUpToAQuarterRadian) {
  const Eigen::Quaterniond q(Rot(0.9, {1, -1, 2}));
  for (double angle : {0.0, 1e-9, 1e-4, 1e-3, 0.01, 0.1, 0.25}) {
    const Eigen::Vector3d axis = Eigen::Vector3d(0.3, 0.8, -0.5).normalized();
    const Eigen::Quaterniond exact = q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis));
    const Eigen::Quaterniond series = TurnBy(q, angle * axis);
    EXPECT_LT((series.coeffs() - exact.coeffs()).cwiseAbs().maxCoeff(), 4e-16) << angle;
    EXPECT_NEAR(series.norm(), 1.0, 4e-16) << angle;
  }
}

// The local-frame model's early exit (after a Newton step below 1e-5 rad)
// skips the iteration that only confirms convergence: from frames one step
// (2e-3 rad) and ten steps old, under stretches up to 1.5 : 0.7, the frame
// it leaves is the one the full iteration reaches, to the bit, and the
// polar rotation to 1e-15 rad. An exit at 0.1 rad stops a step early and
// is caught by the same comparison.
TEST(ExtractRotationTest, NewtonExitGivesTheFrameOfTheFullIteration) {
  const Eigen::Matrix3d axes = Rot(0.4, {1, 2, 3});
  for (double off : {2e-3, 2e-2}) {
    for (const Eigen::Vector3d& s : {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1.1, 0.95, 1.02),
                                     Eigen::Vector3d(1.5, 0.7, 1)}) {
      const Eigen::Matrix3d f = Deformed(Rot(0.7, {0.3, -1, 0.5}), s, axes);
      const Eigen::Quaterniond start(Rot(off, {1, 1, 0}).transpose() * Polar(f));
      Eigen::Quaterniond q = start, full = start, early = start;
      Eigen::Matrix3d r, r_full;
      ExtractRotation(f, q, 8, &r, 1e-5);
      ExtractRotation(f, full, 8, &r_full);
      EXPECT_EQ(q.coeffs(), full.coeffs()) << off << " " << s.transpose();
      EXPECT_EQ(r, r_full);
      EXPECT_LT(Eigen::AngleAxisd(r.transpose() * Polar(f)).angle(), 1e-15);
      ExtractRotation(f, early, 8, nullptr, 0.1);
      EXPECT_NE(early.coeffs(), full.coeffs()) << off << " " << s.transpose();
    }
  }
}

}  // namespace
}  // namespace dynsolid::models
