// Y = K X for one shared element matrix K and a batch of element vectors X:
// the stiffness application's inner product, without Eigen's per-call
// packing of K.
//
// A general GEMM packs both operands on every call. Here K is constant for
// the life of a model, so it is packed once (PackedMatrix), in the order the
// micro-kernel reads it: panels of 8 rows, each panel's columns contiguous
// (8 doubles per column). The batch X (k x count, columns element vectors
// with stride ldx) is read in place; Y (rows padded to a multiple of 8,
// column stride ldy) is written in place.
//
// The micro-kernel keeps an 8 x 6 block of Y in 12 AVX2 registers and runs
// down the shared dimension with fused multiply-adds: every Y entry is one
// fma chain over k in ascending order, so its bits do not depend on the
// batch size, the column's place in the batch or the number of threads
// (and the portable fallback, std::fma in the same order, gives the same
// bits).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace dynsolid::models {

class PackedMatrix {
 public:
  PackedMatrix() = default;
  explicit PackedMatrix(const Eigen::MatrixXd& k);

  int rows() const { return rows_; }
  int cols() const { return cols_; }
  // Rows rounded up to the panel height: Y needs this many rows per column.
  int padded_rows() const { return panels_ * kPanel; }
  int64_t bytes() const { return static_cast<int64_t>(data_.size()) * 8; }
  // K itself (rows x cols), unpacked.
  Eigen::MatrixXd Unpack() const;

  // Y(0 : padded_rows, 0 : count) = K X(0 : cols, 0 : count). Rows past
  // rows() come out zero. x and y must not overlap.
  void Apply(const double* x, int ldx, int count, double* y, int ldy) const;

  static constexpr int kPanel = 8;

 private:
  int rows_ = 0, cols_ = 0, panels_ = 0;
  // Panel p, column j, row r (0..7): data_[(p * cols_ + j) * 8 + r].
  std::vector<double, Eigen::aligned_allocator<double>> data_;
};

// K in single precision, for products whose result only steers an
// iteration (backward Euler's CG: the right-hand side and the residual it
// starts from stay in double; see integrators/backward_euler.h): half the
// bytes, twice the lanes. Panels of 16 rows; the 16 x 6 micro-kernel keeps
// 12 AVX2 registers of 8 floats, runs float fma chains over k in ascending
// order (bits independent of the batch, as PackedMatrix) and widens each
// result to double as it stores it. X is float (its columns rounded from
// double by the caller), Y double.
class PackedMatrixF {
 public:
  PackedMatrixF() = default;
  // K rounded to float entry by entry.
  explicit PackedMatrixF(const PackedMatrix& k);

  int rows() const { return rows_; }
  int cols() const { return cols_; }
  int padded_rows() const { return panels_ * kPanel; }
  int64_t bytes() const { return static_cast<int64_t>(data_.size()) * 4; }
  // The float entries (rows x cols), widened to double.
  Eigen::MatrixXd Unpack() const;

  // Y(0 : padded_rows, 0 : count) = K X(0 : cols, 0 : count), accumulated
  // in float. Rows past rows() come out zero.
  void Apply(const float* x, int ldx, int count, double* y, int ldy) const;

  static constexpr int kPanel = 16;

 private:
  int rows_ = 0, cols_ = 0, panels_ = 0;
  // Panel p, column j, row r (0..15): data_[(p * cols_ + j) * 16 + r].
  std::vector<float, Eigen::aligned_allocator<float>> data_;
};

}  // namespace dynsolid::models
