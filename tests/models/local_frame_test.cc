// The local-frame model's element matrices and deformation measure.
#include "solver/models/local_frame.h"

#include <cmath>
#include <cstdio>
#include <string>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "tests/models/model_fixture.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::models {
namespace {

struct Fixture : test_util::MeshFixture {
  WorkerPool pool{1};
  std::unique_ptr<LocalFrameModel> model;
};

std::unique_ptr<Fixture> Build(const std::string& name, int levels) {
  auto f = std::make_unique<Fixture>();
  // Two materials (stiffer where x > 0.5), so that groups differ by material too.
  test_util::BuildMesh(scene::BuiltinScene(name), levels, test_util::TwoMaterials(1e5, 0.3), *f);
  f->model = std::make_unique<LocalFrameModel>(
      f->layout, DeformationMeasure(f->d.fine(), f->d.elements, f->rest, kForceParts),
      f->d.elements.num_nodes(), f->pool);
  return f;
}

TEST(LocalFrameTest, ElementMatricesAreSymmetricWithConstantsAsTheirNullSpace) {
  auto f = Build("mixed", 2);  // cubic, linear and pyramid elements
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& block = f->layout.blocks[kind];
    ASSERT_GT(block.groups.size(), 0u) << "kind " << kind;
    for (size_t g = 0; g < std::min<size_t>(block.groups.size(), 6); ++g) {
      for (int axis = 0; axis < 3; ++axis) {
        const Eigen::MatrixXd& k = f->model->K(kind, static_cast<int32_t>(g), axis);
        const double scale = k.cwiseAbs().maxCoeff();
        EXPECT_LE((k - k.transpose()).cwiseAbs().maxCoeff(), 1e-12 * scale)
            << "kind " << kind << " group " << g << " axis " << axis << " symmetric";
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(k);
        const Eigen::VectorXd& l = eig.eigenvalues();
        // One zero mode at rounding level; the next is orders of magnitude
        // above it (tricubic B-spline elements are ill-conditioned on their
        // own: about 1e-9 relative for the smallest non-zero mode).
        EXPECT_LE(std::abs(l[0]), 1e-13 * l[l.size() - 1]) << "one zero mode";
        EXPECT_GT(l[1], 1e-11 * l[l.size() - 1]) << "only one zero mode";
        const Eigen::VectorXd ones = Eigen::VectorXd::Ones(k.rows());
        EXPECT_LE((k * ones).norm(), 1e-10 * scale * k.rows()) << "constants are the null space";
      }
    }
  }
}

TEST(LocalFrameTest, GroupsShareMatricesOnRegularGrids) {
  auto f = Build("block4", 2);
  const ElementBlock& cubic = f->layout.blocks[0];
  EXPECT_LT(cubic.groups.size(), static_cast<size_t>(cubic.size()) / 4)
      << cubic.size() << " cubic elements share " << cubic.groups.size() << " matrices";
}

TEST(LocalFrameTest, MeasureIsZeroForRigidMotionAndCatchesStretchAndShear) {
  auto f = Build("block3", 1);
  DeformationMeasure m(f->d.fine(), f->d.elements, f->rest, kForceParts);
  Points delta;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
  const Points moved = (f->rest * r.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  m.Apply(moved, delta);
  EXPECT_LT(delta.cwiseAbs().maxCoeff(), 1e-12);
  // Uniform stretch along x by 1 %: edge terms only; the ends move outward.
  Points stretched = f->rest;
  stretched.col(0) *= 1.01;
  m.Apply(stretched, delta);
  EXPECT_GT(delta.col(0).cwiseAbs().maxCoeff(), 1e-4);
  // Simple shear: corner angles change.
  Points sheared = f->rest;
  sheared.col(0) += 0.01 * f->rest.col(1);
  m.Apply(sheared, delta);
  EXPECT_GT(delta.cwiseAbs().maxCoeff(), 1e-4);
}

// Owner-computes: each node's sum is taken in one global order, so the
// measure and its transpose give the same bits however the nodes are split
// into parts (and so for any thread count), on a mesh with pyramids too.
TEST(LocalFrameTest, MeasureGivesTheSameBitsForAnyPartCount) {
  for (const char* name : {"block3", "mixed"}) {
    auto f = Build(name, 1);
    Points d = f->rest;
    Points y = f->rest;
    for (int64_t i = 0; i < d.rows(); ++i) {
      for (int c = 0; c < 3; ++c) {
        d(i, c) += 0.02 * std::sin(1.7 * i + 0.9 * c);
        y(i, c) = std::cos(0.37 * i - 1.3 * c);
      }
    }
    Points delta1, out1;
    DeformationMeasure one(f->d.fine(), f->d.elements, f->rest, 1);
    one.Apply(d, delta1);
    one.ApplyTranspose(d, y, out1);
    ASSERT_GT(delta1.cwiseAbs().maxCoeff(), 1e-4) << name;
    for (int parts : {2, 3, 5, 8}) {
      DeformationMeasure m(f->d.fine(), f->d.elements, f->rest, parts);
      EXPECT_GE(m.terms_per_pass(), m.num_edges() + m.num_corners());
      Points delta, out;
      m.Apply(d, delta);
      m.ApplyTranspose(d, y, out);
      EXPECT_TRUE(delta == delta1) << name << ": " << parts << " parts";
      EXPECT_TRUE(out == out1) << name << ": " << parts << " parts";
    }
  }
}

// Quadrilaterals run four corners to SIMD lanes; the per-corner path is the
// reference: the same terms summed in another order, so the two agree to
// rounding. The AVX2 and AVX-512 kernels issue the same operations on the
// same values in the same order: the same bits. The transpose is the
// adjoint of the forward's derivative (central differences of y . delta
// along random directions).
TEST(LocalFrameTest, QuadrilateralPathMatchesThePerCornerPathAndItsTransposeIsTheAdjoint) {
  EXPECT_TRUE(QuadPathRuns(QuadPath::kPerCorner));
  EXPECT_TRUE(QuadPathRuns(FastestQuadPath()));
#if defined(__AVX2__) && defined(__FMA__)
  EXPECT_TRUE(QuadPathRuns(QuadPath::kAvx2));
  EXPECT_NE(FastestQuadPath(), QuadPath::kPerCorner);
#endif
  if (!QuadPathRuns(QuadPath::kAvx512)) {
    std::printf("note: this CPU or build has no AVX-512; its kernel is not compared\n");
  }
  for (const char* name : {"block3", "mixed", "torus"}) {
    auto f = Build(name, 1);
    Points d = f->rest, y = f->rest;
    for (int64_t i = 0; i < d.rows(); ++i) {
      for (int c = 0; c < 3; ++c) {
        d(i, c) += 0.03 * std::sin(1.3 * i + 0.7 * c);
        y(i, c) = std::cos(0.41 * i - 1.1 * c);
      }
    }
    const DeformationMeasure corners(f->d.fine(), f->d.elements, f->rest, 3,
                                     QuadPath::kPerCorner);
    EXPECT_EQ(corners.quad_path(), QuadPath::kPerCorner);
    EXPECT_EQ(corners.num_quads(), 0) << name;
    Points dc, tc;
    corners.Apply(d, dc);
    corners.ApplyTranspose(d, y, tc);
    ASSERT_GT(dc.cwiseAbs().maxCoeff(), 1e-4) << name;
    Points d_first, t_first;  // the first SIMD path's results
    for (QuadPath path : {QuadPath::kAvx2, QuadPath::kAvx512}) {
      if (!QuadPathRuns(path)) continue;
      const std::string what = std::string(name) + " " + QuadPathName(path);
      const DeformationMeasure quads(f->d.fine(), f->d.elements, f->rest, 3, path);
      ASSERT_EQ(quads.quad_path(), path) << what;
      EXPECT_EQ(quads.num_corners(), corners.num_corners()) << what;
      EXPECT_GT(quads.num_quads(), 0) << what << ": the quadrilateral path runs";
      Points dq, tq;
      quads.Apply(d, dq);
      quads.ApplyTranspose(d, y, tq);
      EXPECT_LE((dq - dc).cwiseAbs().maxCoeff(), 1e-13 * dc.cwiseAbs().maxCoeff()) << what;
      EXPECT_LE((tq - tc).cwiseAbs().maxCoeff(), 1e-13 * tc.cwiseAbs().maxCoeff()) << what;
      if (d_first.size() == 0) {
        d_first = dq, t_first = tq;
      } else {
        EXPECT_TRUE(dq == d_first) << what << ": not the AVX2 kernel's bits";
        EXPECT_TRUE(tq == t_first) << what << ": not the AVX2 kernel's bits";
      }
      for (uint32_t seed : {1u, 2u, 3u}) {
        const Points v = test_util::RandomPoints(d.rows(), seed);
        const double h = 1e-6;
        Points plus, minus;
        quads.Apply(d + h * v, plus);
        quads.Apply(d - h * v, minus);
        const double fd = test_util::Dot(y, plus - minus) / (2 * h);
        const double analytic = test_util::Dot(tq, v);
        EXPECT_NEAR(analytic, fd, 1e-6 * std::abs(fd)) << what << " seed " << seed;
      }
    }
  }
}

// Single-precision element products (the stepping default): the shared
// matrices and the rotated local deformation rounded to float for the
// product only. Forces within 1e-6 of the double products (relative to
// their largest entry; 2e-8 measured), the energy within 1e-7 (2e-9),
// zero force for a rigid motion still; ExactForces runs the same rounded
// entries in double (6e-9 from the double model: the matrices' rounding).
TEST(LocalFrameTest, FloatProductsStayWithinRoundingOfDoubleProducts) {
  auto f = Build("mixed", 2);  // cubic, linear and pyramid elements
  const int32_t nodes = f->d.elements.num_nodes();
  // Every group through its dense matrices (quadrature_group_size 0).
  LocalFrameModel dbl(f->layout, DeformationMeasure(f->d.fine(), f->d.elements, f->rest, kForceParts),
                      nodes, f->pool, nullptr, /*float_products=*/false, 0);
  LocalFrameModel flt(f->layout, DeformationMeasure(f->d.fine(), f->d.elements, f->rest, kForceParts),
                      nodes, f->pool, nullptr, /*float_products=*/true, 0);
  EXPECT_TRUE(flt.float_products());
  EXPECT_LT(flt.shared_matrix_bytes(), dbl.shared_matrix_bytes()) << "float matrices only";
  Points d = f->rest;
  for (int64_t i = 0; i < d.rows(); ++i) {
    d(i, 0) += 0.02 * std::sin(1.0 + 2.0 * i);
    d(i, 2) += 0.015 * std::cos(3.0 * i);
  }
  d = d * Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix().transpose();
  Points gd, gf, ge;
  const double ed = dbl.Forces(d, gd);
  flt.ResetFrames();
  const double ef = flt.Forces(d, gf);
  flt.ResetFrames();
  const double ee = flt.ExactForces(d, ge);
  const double scale = gd.cwiseAbs().maxCoeff();
  ASSERT_GT(scale, 0);
  EXPECT_GT((gf - gd).cwiseAbs().maxCoeff(), 0) << "the float path ran";
  EXPECT_LE((gf - gd).cwiseAbs().maxCoeff(), 1e-6 * scale);
  EXPECT_NEAR(ef, ed, 1e-7 * ed);
  // ExactForces: the rounded matrices' entries in double arithmetic, so
  // only the matrices' rounding separates it from dbl.
  EXPECT_LE((ge - gd).cwiseAbs().maxCoeff(), 1e-7 * scale);
  EXPECT_NEAR(ee, ed, 1e-7 * ed);
  // Rigid motion: delta is zero before any rounding.
  const Eigen::Matrix3d r = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
  const Points moved = (f->rest * r.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  flt.ResetFrames();
  flt.Forces(moved, gf);
  EXPECT_LE(gf.cwiseAbs().maxCoeff(), 1e-10 * scale);
}

// Cubic elements applied at their quadrature points (cubic_quadrature.h)
// give the dense matrices' products: on a curved mesh (every element its own
// shape) with a graded material (every sample its own value), in double to
// rounding, in float within the float products' rounding.
TEST(LocalFrameTest, QuadraturePointsGiveTheDenseProducts) {
  for (const auto& [name, levels] : {std::pair{"torus", 1}, std::pair{"mixed", 2}}) {
    auto f = std::make_unique<Fixture>();
    test_util::BuildMesh(scene::BuiltinScene(name), levels,
                         [](const Eigen::Vector3d& x, int32_t) {
                           return MaterialPoint{1e5 * (1.5 + std::sin(2.0 * x.x() + x.z())),
                                                0.3 + 0.1 * std::cos(3.0 * x.y()), 1000, 0};
                         },
                         *f);
    const int32_t nodes = f->d.elements.num_nodes();
    auto make = [&](bool float_products, int32_t group_size) {
      return std::make_unique<LocalFrameModel>(
          f->layout, DeformationMeasure(f->d.fine(), f->d.elements, f->rest, kForceParts), nodes,
          f->pool, nullptr, float_products, group_size);
    };
    const auto dense = make(false, 0), quad = make(false, 1 << 30), quad_f = make(true, 1 << 30);
    const int64_t cubic = f->layout.blocks[0].size();
    ASSERT_GT(cubic, 0) << name;
    // A pooled group's matrices, made from its quadrature points, are the
    // integrated ones to rounding.
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::MatrixXd kq = quad->K(0, 0, axis), kd = dense->K(0, 0, axis);
      EXPECT_LE((kq - kd).cwiseAbs().maxCoeff(), 1e-13 * kd.cwiseAbs().maxCoeff()) << name;
    }
    EXPECT_EQ(dense->quadrature_elements(), 0);
    EXPECT_EQ(quad->quadrature_elements(), cubic);
    EXPECT_EQ(quad->integrated_groups(), f->layout.blocks[1].groups.size() +
                                             f->layout.blocks[2].groups.size())
        << "no cubic matrix integrated";
    Points d = f->rest;
    for (int64_t i = 0; i < d.rows(); ++i) {
      d(i, 0) += 0.02 * std::sin(1.0 + 2.0 * i);
      d(i, 1) -= 0.01 * std::sin(0.5 * i);
      d(i, 2) += 0.015 * std::cos(3.0 * i);
    }
    d = d * Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 1, 0).normalized())
                .toRotationMatrix()
                .transpose();
    Points gd, gq, gf;
    const double ed = dense->Forces(d, gd), eq = quad->Forces(d, gq), ef = quad_f->Forces(d, gf);
    const double scale = gd.cwiseAbs().maxCoeff();
    ASSERT_GT(scale, 0);
    EXPECT_LE((gq - gd).cwiseAbs().maxCoeff(), 1e-11 * scale) << name;
    EXPECT_NEAR(eq, ed, 1e-11 * ed) << name;
    EXPECT_LE((gf - gd).cwiseAbs().maxCoeff(), 1e-6 * scale) << name;
    EXPECT_NEAR(ef, ed, 1e-6 * ed) << name;
    std::printf("%s: %lld cubic elements at their quadrature points; force differs from the "
                "dense products by %.2g (double) and %.2g (float) of its largest entry\n",
                name, static_cast<long long>(cubic), (gq - gd).cwiseAbs().maxCoeff() / scale,
                (gf - gd).cwiseAbs().maxCoeff() / scale);
    // Rigid motion: no force.
    const Eigen::Matrix3d r =
        Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
    const Points moved = (f->rest * r.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
    quad_f->ResetFrames();
    quad_f->Forces(moved, gf);
    EXPECT_LE(gf.cwiseAbs().maxCoeff(), 1e-10 * scale) << name;
    // The same bits for any number of threads.
    WorkerPool two(2);
    LocalFrameModel quad_two(f->layout,
                             DeformationMeasure(f->d.fine(), f->d.elements, f->rest, kForceParts),
                             nodes, two, nullptr, true, 1 << 30);
    Points g1, g2;
    quad_f->ResetFrames();
    quad_f->Forces(d, g1);
    quad_two.Forces(d, g2);
    EXPECT_EQ(g1, g2) << name;
  }
}

}  // namespace
}  // namespace dynsolid::models
