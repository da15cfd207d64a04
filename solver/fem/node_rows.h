// The node matrix A (FEM nodes x control points, d = A p) in the compact
// form the per-step products stream: each row's column indices in 16 bits
// when there are at most 65536 control points, and its values in single
// precision when every value is exactly a float (the subdivision weights of
// regular regions are dyadic fractions: 1/8, 3/64, ...). The values are
// the matrix's own bits either way and the products run in double, so the
// results are the double matrix's; what changes is the bytes per entry
// (12 -> 6 on a regular block), and the products are bound by them: at 216
// thousand elements A has 6.9 million entries, 82 MB in Eigen's form,
// streamed twice per step.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/SparseCore>

#include "solver/mesh/points.h"

namespace dynsolid::fem {

class NodeRows {
 public:
  NodeRows() = default;
  explicit NodeRows(const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>& a);

  int64_t rows() const { return static_cast<int64_t>(start_.size()) - 1; }
  int64_t cols() const { return cols_; }
  bool short_columns() const { return narrow_; }
  bool float_values() const { return exact_; }
  int64_t bytes() const;

  // Rows [r0, r1) of out = A p (out must have rows() rows; p cols() rows).
  // Each row's sum runs over its entries in stored order.
  void Multiply(const Points& p, int64_t r0, int64_t r1, Points& out) const;

  // A p, all rows.
  Points Multiply(const Points& p) const;
  // Row i of A p (the same bits as Multiply's row i).
  Eigen::Vector3d Row(const Points& p, int64_t i) const;

  // out (cols() by 3) = A[r0:r1]^T g[r0:r1]: the rows' entries added in
  // row order. out is resized and overwritten.
  void MultiplyTransposed(const Points& g, int64_t r0, int64_t r1, Points& out) const;

 private:
  // Rows [r0, r1) of A p into out (row r0 first, 3 doubles a row).
  void MultiplyInto(const Points& p, int64_t r0, int64_t r1, double* out) const;
  // f(columns, values) with the arrays this matrix keeps (16 or 32-bit
  // columns, float or double values).
  template <typename F>
  void WithArrays(F&& f) const {
    if (narrow_ && exact_) {
      f(col16_.data(), val32_.data());
    } else if (narrow_) {
      f(col16_.data(), val64_.data());
    } else if (exact_) {
      f(col32_.data(), val32_.data());
    } else {
      f(col32_.data(), val64_.data());
    }
  }

  int64_t cols_ = 0;
  bool narrow_ = true, exact_ = true;
  std::vector<int64_t> start_{0};  // row i's entries: [start_[i], start_[i + 1])
  std::vector<uint16_t> col16_;
  std::vector<int32_t> col32_;
  std::vector<float> val32_;
  std::vector<double> val64_;
};

}  // namespace dynsolid::fem
