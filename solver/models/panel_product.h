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

// K (rows x cols) packed once in panels of kPanel rows, its entries of type
// T: double (PackedMatrix, panels of 8) or float (PackedMatrixF, panels of
// 16). A panel is 64 bytes high: two AVX2 registers of 4 doubles or 8
// floats.
//
// PackedMatrixF holds K rounded to float, for products whose result is
// accurate enough at float rounding: backward Euler's CG (the right-hand
// side and the residual it starts from stay in double; see
// integrators/backward_euler.h) and the local-frame model's stepping
// products (solver.element_products; models/local_frame.h). Half the
// bytes, twice the lanes: its 16 x 6 micro-kernel keeps 12 AVX2 registers
// of 8 floats and runs float fma chains over k in ascending order (bits
// independent of the batch, as in double). X is then float (its columns
// rounded from double by the caller); Y is double either way (float
// results widened as they are stored).
template <typename T>
class PackedPanels {
 public:
  static constexpr int kPanel = 64 / static_cast<int>(sizeof(T));

  PackedPanels() = default;
  // K's entries rounded to T.
  explicit PackedPanels(const Eigen::MatrixXd& k);
  // The same matrix in the other precision (through its double entries).
  template <typename U>
  explicit PackedPanels(const PackedPanels<U>& k) : PackedPanels(k.Unpack()) {}

  int rows() const { return rows_; }
  int cols() const { return cols_; }
  // Rows rounded up to the panel height: Y needs this many rows per column.
  int padded_rows() const { return panels_ * kPanel; }
  int64_t bytes() const { return static_cast<int64_t>(data_.size() * sizeof(T)); }
  // K itself (rows x cols), unpacked (and widened to double).
  Eigen::MatrixXd Unpack() const;

  // Y(0 : padded_rows, 0 : count) = K X(0 : cols, 0 : count), accumulated
  // in T. Rows past rows() come out zero. x and y must not overlap.
  void Apply(const T* x, int ldx, int count, double* y, int ldy) const;

 private:
  int rows_ = 0, cols_ = 0, panels_ = 0;
  // Panel p, column j, row r (0 .. kPanel - 1): data_[(p * cols_ + j) * kPanel + r].
  std::vector<T, Eigen::aligned_allocator<T>> data_;
};

extern template class PackedPanels<double>;
extern template class PackedPanels<float>;
using PackedMatrix = PackedPanels<double>;
using PackedMatrixF = PackedPanels<float>;

}  // namespace dynsolid::models
