// The sparse Cholesky factor of a symmetric positive definite matrix S on
// its free rows and columns (fixed ones left out: dimension reduction), made
// once and applied to the three columns (x, y, z) of a #rows by 3 Points
// (or to one column).
//
// CHOLMOD (SuiteSparse, Debian's libsuitesparse-dev) makes it: the better
// fill-reducing order of METIS's nested dissection and AMD, a supernodal
// factorization (dense blocks, BLAS), then the factor turned simplicial for
// the solves, whose loops CHOLMOD specializes for a few right-hand sides
// (docs/architecture.md, "The explicit step's factor"). Single-threaded and
// without OpenMP, so its bits depend on the values alone, never on the
// simulation's thread count.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "solver/common/sparse_matrix.h"
#include "solver/mesh/points.h"

namespace dynsolid::integrators {

class ReducedCholesky {
 public:
  ReducedCholesky();
  ~ReducedCholesky();
  ReducedCholesky(ReducedCholesky&&) noexcept;
  ReducedCholesky& operator=(ReducedCholesky&&) noexcept;

  // Factors S on the rows with fixed[i] == 0 (fixed may be empty: none).
  // S is symmetric and only its upper triangle (row i's entries j >= i) is
  // read: a caller may leave the rest out. False, with the factor cleared,
  // where S is not positive definite there (or CHOLMOD runs out of memory).
  //
  // How the solves run. kSimplicial (the default): the supernodal factor is
  // turned into a simplicial LL^T, whose loops CHOLMOD specializes for a
  // few right-hand sides (the central-difference system's three columns:
  // 5.6 ms a step at 12^3 against 6.0 ms supernodal). kSupernodal: the
  // supernodes stay and the solves go through the BLAS (one column, as
  // backward Euler's preconditioner: 14.5 ms against 17.5 ms a step at
  // 12^3, 44 against 54.5 at 16^3; measured with OpenBLAS, AMD EPYC).
  enum class Solves { kSimplicial, kSupernodal };
  bool Factor(const SparseMatrix& s, const std::vector<uint8_t>& fixed,
              Solves solves = Solves::kSimplicial);
  bool factored() const;

  // x = S_ff^-1 b_f on the free rows, zero on the fixed ones. x and b are
  // #rows by 3 and may not alias. Allocates nothing after the first call.
  void Solve(const Points& b, Points& x);
  // The same for one column: b and x hold #rows values each (a flat vector
  // of DOFs, such as a row-major #control by 3 Points over 3 #control DOFs).
  void SolveVector(const double* b, double* x);

  // Entries of the factor L (a measure of its memory: 12 bytes each).
  int64_t factor_nonzeros() const;

 private:
  // b and x row-major, #rows by `columns` (1 or 3).
  void SolveRows(const double* b, double* x, int columns);

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dynsolid::integrators
