#include "solver/models/rotation.h"

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

}  // namespace
}  // namespace dynsolid::models
