// The solver's row-major sparse matrix: Eigen's, with a move that moves.
//
// Eigen 3.4's SparseMatrix declares no move constructor and no move
// assignment, so std::move of one falls back to the copy: all of its
// arrays copied into fresh memory. A discretization's node matrix is
// megabytes and passes through a dozen moves (StatusOr, Discretization,
// Hierarchy, Level) in every build. This type moves by swapping the
// arrays (O(1); the moved-from matrix is left empty) and is otherwise
// Eigen's: every expression, iterator and function of Eigen::SparseMatrix
// takes it, and it converts both ways.
#pragma once

#include <cstdint>
#include <utility>

#include <Eigen/SparseCore>

namespace dynsolid {

class SparseMatrix : public Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t> {
 public:
  using Base = Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>;
  using Base::Base;
  using Base::operator=;

  SparseMatrix() = default;
  SparseMatrix(const SparseMatrix&) = default;
  SparseMatrix(SparseMatrix&& other) noexcept { swap(other); }
  SparseMatrix(const Base& other) : Base(other) {}
  SparseMatrix(Base&& other) noexcept { swap(other); }
  // Any sparse expression (a product, a transpose, a sparse view).
  template <typename Other>
  SparseMatrix(const Eigen::SparseMatrixBase<Other>& other) : Base(other) {}

  SparseMatrix& operator=(const SparseMatrix& other) {
    Base::operator=(other);
    return *this;
  }
  SparseMatrix& operator=(SparseMatrix&& other) noexcept {
    return *this = static_cast<Base&&>(other);
  }
  // The old arrays are freed here, the moved-from matrix left empty.
  SparseMatrix& operator=(Base&& other) noexcept {
    Base taken;
    taken.swap(other);
    swap(taken);
    return *this;
  }
};

}  // namespace dynsolid
