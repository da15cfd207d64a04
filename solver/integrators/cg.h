// Preconditioned conjugate gradient for S X = B with three right-hand sides
// (x, y, z) sharing one sparse SPD matrix S, a Jacobi or incomplete
// Cholesky preconditioner (built once in Setup: S is constant), and
// fixed rows (dimension reduction: fixed unknowns keep their value in X and
// leave the system). Workspace is allocated in Setup, never in Solve.
#pragma once

#include <cstdint>
#include <vector>

#include <memory>

#include <Eigen/SparseCore>

#include "solver/common/sparse_matrix.h"
#include "solver/mesh/points.h"

namespace dynsolid::integrators {

using SparseMatrix = dynsolid::SparseMatrix;  // Eigen's, with a real move (common/sparse_matrix.h)

enum class Preconditioner {
  kJacobi,               // diagonal
  kIncompleteCholesky,   // Eigen's IncompleteCholesky (threshold IC, AMD order)
  // The reduced matrix factored exactly: dense Cholesky up to kDenseRows
  // rows (a few hundred control points' mass matrix is a quarter full or
  // more, and its sparse factor fills in), a sparse LDL^T up to
  // kDirectRows; above that, or where the factor fails, incomplete
  // Cholesky. CG then stops after an iteration.
  kDirect,
};

struct CgStats {
  int32_t iterations = 0;       // summed over the three columns
  int32_t max_iterations = 0;   // of the slowest column
  double relative_residual = 0; // largest over the columns at exit
  bool converged = true;
};

// P^-1 for a sparse SPD matrix S, applied to each of the three columns:
// Jacobi or incomplete Cholesky of S with fixed rows and columns replaced by
// the identity (it then maps fixed rows to zero).
class ColumnPreconditioner {
 public:
  static constexpr int64_t kDenseRows = 1024, kDirectRows = 4096;
  ColumnPreconditioner();
  ~ColumnPreconditioner();
  ColumnPreconditioner(ColumnPreconditioner&&) noexcept;
  ColumnPreconditioner& operator=(ColumnPreconditioner&&) noexcept;

  void Setup(const SparseMatrix& s, const std::vector<uint8_t>& fixed, Preconditioner kind);
  // z = P^-1 r (#rows by 3); fixed rows of z are zero.
  void Apply(const Points& r, Points& z) const;
  // Whether P is S itself on the free rows (kDirect's factor was made):
  // Apply then solves S z = r there.
  bool exact() const { return direct_ != nullptr; }

 private:
  struct Ic;
  struct Direct;
  Eigen::VectorXd inv_diag_;
  std::unique_ptr<Ic> ic_;
  std::unique_ptr<Direct> direct_;
};

class ConjugateGradient {
 public:
  ConjugateGradient();
  ~ConjugateGradient();
  ConjugateGradient(ConjugateGradient&&) noexcept;
  ConjugateGradient& operator=(ConjugateGradient&&) noexcept;

  // `s` must outlive the solver. fixed[i] != 0 marks row i fixed (may be empty).
  void Setup(const SparseMatrix* s, std::vector<uint8_t> fixed,
             Preconditioner preconditioner = Preconditioner::kIncompleteCholesky);

  // X holds the initial guess (and the fixed values) on entry, the solution
  // on exit. Stops per column at ||r|| <= tolerance ||b_free||, where b_free
  // is the right-hand side of the reduced system.
  // `floor` (optional, one per column): an absolute residual norm below
  // which a column is done whatever its relative residual (a right-hand
  // side of rounding noise, as at rest, is not chased to 1e-4 of itself).
  CgStats Solve(const Points& b, Points& x, double tolerance, int max_iterations,
                const double* floor = nullptr);

  const std::vector<uint8_t>& fixed() const { return fixed_; }

 private:
  void MaskFixed(Points& m) const;
  void Precondition() { pre_.Apply(r_, z_); }

  const SparseMatrix* s_ = nullptr;
  std::vector<uint8_t> fixed_;
  bool any_fixed_ = false;
  ColumnPreconditioner pre_;
  Points r_, z_, p_, q_, b0_;
};

}  // namespace dynsolid::integrators
