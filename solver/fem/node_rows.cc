#include "solver/fem/node_rows.h"

namespace dynsolid::fem {

NodeRows::NodeRows(const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>& a)
    : cols_(a.cols()) {
  const int64_t n = a.rows();
  start_.resize(n + 1);
  start_[0] = 0;
  bool exact = true;
  for (int64_t i = 0; i < n; ++i) {
    int64_t k = start_[i];
    for (Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>::InnerIterator it(a, i); it;
         ++it, ++k) {
      const double v = it.value();
      exact = exact && static_cast<double>(static_cast<float>(v)) == v;
    }
    start_[i + 1] = k;
  }
  const int64_t nnz = start_[n];
  narrow_ = cols_ <= 65536;
  exact_ = exact;
  if (narrow_) {
    col16_.reserve(nnz);
  } else {
    col32_.reserve(nnz);
  }
  if (exact) {
    val32_.reserve(nnz);
  } else {
    val64_.reserve(nnz);
  }
  for (int64_t i = 0; i < n; ++i) {
    for (Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>::InnerIterator it(a, i); it;
         ++it) {
      if (narrow_) {
        col16_.push_back(static_cast<uint16_t>(it.col()));
      } else {
        col32_.push_back(static_cast<int32_t>(it.col()));
      }
      if (exact) {
        val32_.push_back(static_cast<float>(it.value()));
      } else {
        val64_.push_back(it.value());
      }
    }
  }
}

int64_t NodeRows::bytes() const {
  return static_cast<int64_t>(start_.size() * sizeof(int64_t) + col16_.size() * 2 +
                              col32_.size() * 4 + val32_.size() * 4 + val64_.size() * 8);
}

namespace {

template <typename Col, typename Val>
void MultiplyRange(const int64_t* start, const Col* col, const Val* val, const double* p,
                   int64_t r0, int64_t r1, double* out) {
  // out points at row r0's sums.
  for (int64_t i = r0; i < r1; ++i) {
    double x = 0, y = 0, z = 0;
    for (int64_t k = start[i]; k < start[i + 1]; ++k) {
      const double v = static_cast<double>(val[k]);
      const double* q = p + 3 * static_cast<int64_t>(col[k]);
      x += v * q[0];
      y += v * q[1];
      z += v * q[2];
    }
    double* o = out + 3 * (i - r0);
    o[0] = x;
    o[1] = y;
    o[2] = z;
  }
}

template <typename Col, typename Val>
void MultiplyTransposedRange(const int64_t* start, const Col* col, const Val* val,
                             const double* g, int64_t r0, int64_t r1, double* out) {
  for (int64_t i = r0; i < r1; ++i) {
    const double gx = g[3 * i], gy = g[3 * i + 1], gz = g[3 * i + 2];
    for (int64_t k = start[i]; k < start[i + 1]; ++k) {
      const double v = static_cast<double>(val[k]);
      double* o = out + 3 * static_cast<int64_t>(col[k]);
      o[0] += v * gx;
      o[1] += v * gy;
      o[2] += v * gz;
    }
  }
}

}  // namespace

void NodeRows::Multiply(const Points& p, int64_t r0, int64_t r1, Points& out) const {
  MultiplyInto(p, r0, r1, out.data() + 3 * r0);
}

void NodeRows::MultiplyInto(const Points& p, int64_t r0, int64_t r1, double* out) const {
  WithArrays([&](const auto* col, const auto* val) {
    MultiplyRange(start_.data(), col, val, p.data(), r0, r1, out);
  });
}

Points NodeRows::Multiply(const Points& p) const {
  Points out(rows(), 3);
  Multiply(p, 0, rows(), out);
  return out;
}

Eigen::Vector3d NodeRows::Row(const Points& p, int64_t i) const {
  Eigen::Vector3d out;
  MultiplyInto(p, i, i + 1, out.data());
  return out;
}

void NodeRows::MultiplyTransposed(const Points& g, int64_t r0, int64_t r1, Points& out) const {
  out.setZero(cols_, 3);
  WithArrays([&](const auto* col, const auto* val) {
    MultiplyTransposedRange(start_.data(), col, val, g.data(), r0, r1, out.data());
  });
}

}  // namespace dynsolid::fem
