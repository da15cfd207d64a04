// ConjugateGradient with its preconditioners on mass-like matrices (a
// control mesh's Mt: SPD, each point coupled to its neighbours on a grid),
// against a dense reference solve: the exact preconditioner (kDirect, dense
// and sparse factors) makes CG stop after one iteration per column with the
// reference's answer, keeps fixed rows, and falls back to incomplete
// Cholesky where the matrix is not positive definite. The explicit step's
// factor (ReducedCholesky) solves the reduced system to rounding, and
// CentralDifference with it steps as with CG.
#include "solver/integrators/cg.h"
#include "solver/integrators/central_difference.h"
#include "solver/integrators/reduced_cholesky.h"

#include <cmath>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

namespace dynsolid::integrators {
namespace {

// A consistent-mass-like matrix on an nx x ny x nz grid of points: each
// point coupled to its 26 neighbours with weights falling off by distance,
// the diagonal dominant (SPD), scaled by a smooth density.
SparseMatrix GridMass(int nx, int ny, int nz) {
  const int n = nx * ny * nz;
  auto id = [&](int i, int j, int k) { return (k * ny + j) * nx + i; };
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        const double rho = 1.0 + 0.5 * std::sin(0.3 * i + 0.7 * j + 1.1 * k);
        for (int dk = -1; dk <= 1; ++dk) {
          for (int dj = -1; dj <= 1; ++dj) {
            for (int di = -1; di <= 1; ++di) {
              const int a = i + di, b = j + dj, c = k + dk;
              if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
              const int d = std::abs(di) + std::abs(dj) + std::abs(dk);
              const double w = d == 0 ? 8.0 : 1.0 / (4 << d);
              // Symmetric: the mean of both points' densities.
              const double rho_b = 1.0 + 0.5 * std::sin(0.3 * a + 0.7 * b + 1.1 * c);
              t.emplace_back(id(i, j, k), id(a, b, c), w * 0.5 * (rho + rho_b));
            }
          }
        }
      }
    }
  }
  SparseMatrix m(n, n);
  m.setFromTriplets(t.begin(), t.end());
  m.makeCompressed();
  return m;
}

Points RightHandSide(int n) {
  Points b(n, 3);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) b(i, c) = std::cos(0.37 * i + 1.3 * c) + 0.1 * c;
  }
  return b;
}

// The reduced system's solution (fixed rows keep x0's values), densely.
Points Reference(const SparseMatrix& s, const std::vector<uint8_t>& fixed, const Points& b,
                 const Points& x0) {
  const Eigen::MatrixXd d = Eigen::MatrixXd(s);
  const int n = static_cast<int>(s.rows());
  std::vector<int> free_rows;
  for (int i = 0; i < n; ++i) {
    if (!fixed[i]) free_rows.push_back(i);
  }
  const int f = static_cast<int>(free_rows.size());
  Eigen::MatrixXd a(f, f), rhs(f, 3);
  for (int r = 0; r < f; ++r) {
    for (int c = 0; c < f; ++c) a(r, c) = d(free_rows[r], free_rows[c]);
    for (int k = 0; k < 3; ++k) {
      double v = b(free_rows[r], k);
      for (int i = 0; i < n; ++i) {
        if (fixed[i]) v -= d(free_rows[r], i) * x0(i, k);
      }
      rhs(r, k) = v;
    }
  }
  const Eigen::MatrixXd y = a.ldlt().solve(rhs);
  Points x = x0;
  for (int r = 0; r < f; ++r) x.row(free_rows[r]) = y.row(r);
  return x;
}

void ExpectSolves(const SparseMatrix& s, int expected_iterations_at_most) {
  const int n = static_cast<int>(s.rows());
  std::vector<uint8_t> fixed(n, 0);
  for (int i = 0; i < n; i += 7) fixed[i] = 1;
  const Points b = RightHandSide(n);
  Points x0 = Points::Zero(n, 3);
  for (int i = 0; i < n; ++i) {
    if (fixed[i]) x0.row(i) << 0.01 * i, -0.02, 0.5;
  }
  const Points ref = Reference(s, fixed, b, x0);

  ConjugateGradient cg;
  cg.Setup(&s, fixed, Preconditioner::kDirect);
  Points x = x0;
  const CgStats stats = cg.Solve(b, x, 1e-10, 100);
  EXPECT_TRUE(stats.converged);
  EXPECT_LE(stats.max_iterations, expected_iterations_at_most);
  EXPECT_LE((x - ref).cwiseAbs().maxCoeff(), 1e-10 * ref.cwiseAbs().maxCoeff());
  for (int i = 0; i < n; ++i) {
    if (fixed[i]) EXPECT_EQ(x.row(i), x0.row(i)) << "fixed row " << i;
  }

  // Incomplete Cholesky reaches the same answer, in more iterations.
  ConjugateGradient ic;
  ic.Setup(&s, fixed, Preconditioner::kIncompleteCholesky);
  Points xi = x0;
  const CgStats ic_stats = ic.Solve(b, xi, 1e-10, 200);
  EXPECT_TRUE(ic_stats.converged);
  EXPECT_GE(ic_stats.max_iterations, stats.max_iterations);
  EXPECT_LE((xi - ref).cwiseAbs().maxCoeff(), 1e-8 * ref.cwiseAbs().maxCoeff());
}

TEST(CgTest, ADenseExactPreconditionerSolvesInOneIterationWithFixedRows) {
  const SparseMatrix s = GridMass(6, 5, 7);  // 210 points: the dense factor
  ASSERT_LE(s.rows(), ColumnPreconditioner::kDenseRows);
  ExpectSolves(s, 1);
}

TEST(CgTest, ASparseExactPreconditionerSolvesInOneIterationWithFixedRows) {
  const SparseMatrix s = GridMass(12, 11, 10);  // 1320 points: sparse LDL^T
  ASSERT_GT(s.rows(), ColumnPreconditioner::kDenseRows);
  ASSERT_LE(s.rows(), ColumnPreconditioner::kDirectRows);
  ExpectSolves(s, 1);
}

TEST(CgTest, TheExactPreconditionerAppliesTheInverseOnFreeRowsAndZeroOnFixed) {
  const SparseMatrix s = GridMass(4, 4, 4);
  const int n = static_cast<int>(s.rows());
  std::vector<uint8_t> fixed(n, 0);
  fixed[3] = fixed[40] = 1;
  ColumnPreconditioner p;
  p.Setup(s, fixed, Preconditioner::kDirect);
  ASSERT_TRUE(p.exact());
  Points r = RightHandSide(n), z(n, 3);
  r.row(3).setZero();
  r.row(40).setZero();
  p.Apply(r, z);
  const Points ref = Reference(s, fixed, r, Points::Zero(n, 3));
  EXPECT_LE((z - ref).cwiseAbs().maxCoeff(), 1e-12 * ref.cwiseAbs().maxCoeff());
  EXPECT_EQ(z.row(3), Eigen::RowVector3d::Zero());
  EXPECT_EQ(z.row(40), Eigen::RowVector3d::Zero());
}

TEST(CgTest, AnIndefiniteMatrixGetsNoExactFactor) {
  SparseMatrix s = GridMass(3, 3, 3);
  s.coeffRef(13, 13) = -5.0;  // one negative pivot: not positive definite
  std::vector<uint8_t> fixed(s.rows(), 0);
  ColumnPreconditioner p;
  p.Setup(s, fixed, Preconditioner::kDirect);
  EXPECT_FALSE(p.exact());
  // A fixed row there leaves the rest positive definite: factored.
  fixed[13] = 1;
  p.Setup(s, fixed, Preconditioner::kDirect);
  EXPECT_TRUE(p.exact());
}

TEST(ReducedCholeskyTest, SolvesTheFreeRowsAndZeroesTheFixed) {
  const SparseMatrix s = GridMass(9, 8, 7);
  const int n = static_cast<int>(s.rows());
  std::vector<uint8_t> fixed(n, 0);
  for (int i = 0; i < n; i += 5) fixed[i] = 1;
  ReducedCholesky factor;
  ASSERT_TRUE(factor.Factor(s, fixed));
  EXPECT_TRUE(factor.factored());
  EXPECT_GT(factor.factor_nonzeros(), 0);
  const Points b = RightHandSide(n);
  Points x;
  factor.Solve(b, x);
  const Points ref = Reference(s, fixed, b, Points::Zero(n, 3));
  EXPECT_LE((x - ref).cwiseAbs().maxCoeff(), 1e-12 * ref.cwiseAbs().maxCoeff());
  for (int i = 0; i < n; i += 5) EXPECT_EQ(x.row(i), Eigen::RowVector3d::Zero()) << i;
  // Solving again gives the same bits (the workspace is reused).
  Points again;
  factor.Solve(b, again);
  EXPECT_TRUE(again == x);
}

TEST(ReducedCholeskyTest, AnIndefiniteMatrixIsNotFactored) {
  SparseMatrix s = GridMass(3, 3, 3);
  s.coeffRef(13, 13) = -5.0;
  std::vector<uint8_t> fixed(s.rows(), 0);
  ReducedCholesky factor;
  EXPECT_FALSE(factor.Factor(s, fixed));
  EXPECT_FALSE(factor.factored());
  fixed[13] = 1;  // the rest is positive definite
  EXPECT_TRUE(factor.Factor(s, fixed));
  // Everything fixed: nothing to solve, zeros.
  std::vector<uint8_t> all(s.rows(), 1);
  EXPECT_TRUE(factor.Factor(s, all));
  Points x;
  factor.Solve(RightHandSide(static_cast<int>(s.rows())), x);
  EXPECT_EQ(x.cwiseAbs().maxCoeff(), 0.0);
}

// Central differences with the factor against CG to 1e-13 (incomplete
// Cholesky: 512 points is above kExactRows), with damping and fixed rows,
// over steps whose forces depend on the state: within 1e-9 of the motion.
TEST(ReducedCholeskyTest, CentralDifferenceStepsAsWithCg) {
  const SparseMatrix mt = GridMass(8, 8, 8);
  const SparseMatrix dt = 3.0 * mt;
  const int n = static_cast<int>(mt.rows());
  ASSERT_GT(n, CentralDifference::kExactRows);
  std::vector<uint8_t> fixed(n, 0);
  for (int i = 0; i < 64; ++i) fixed[i] = 1;  // the bottom layer
  const double h = 1e-3;
  CentralDifference factored, cg;
  factored.Setup(&mt, &dt, h, fixed, CentralDifference::Solve::kFactored);
  cg.Setup(&mt, &dt, h, fixed, CentralDifference::Solve::kCg);
  ASSERT_TRUE(factored.factored());
  ASSERT_FALSE(cg.factored());
  const Points rest = RightHandSide(n);
  Points pa = rest, pa_prev = rest, pb = rest, pb_prev = rest, next(n, 3), force(n, 3);
  int iterations = 0;
  for (int step = 0; step < 20; ++step) {
    // A spring to rest plus a constant push: F = -k (p - rest) + f.
    force = -50.0 * (pa - rest);
    force.col(0).array() += 1.0;
    const CgStats a = factored.Step(pa, pa_prev, force, next, 1e-4, 500);
    EXPECT_EQ(a.iterations, 0);
    pa_prev = pa;
    pa = next;
    force = -50.0 * (pb - rest);
    force.col(0).array() += 1.0;
    const CgStats b = cg.Step(pb, pb_prev, force, next, 1e-13, 500);
    iterations += b.iterations;
    pb_prev = pb;
    pb = next;
  }
  EXPECT_GT(iterations, 0);
  const double moved = (pb - rest).cwiseAbs().maxCoeff();
  ASSERT_GT(moved, 0);
  EXPECT_LT((pa - pb).cwiseAbs().maxCoeff(), 1e-9 * moved);
  for (int i = 0; i < 64; ++i) EXPECT_EQ(pa.row(i), rest.row(i)) << i;
}

}  // namespace
}  // namespace dynsolid::integrators
