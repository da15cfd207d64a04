#include "solver/fem/node_rows.h"

namespace dynsolid::fem {

NodeRows::NodeRows(const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>& a)
    : cols_(a.cols()) {
  if (!a.isCompressed()) {
    Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t> compressed = a;
    compressed.makeCompressed();
    *this = NodeRows(compressed);
    return;
  }
  // Straight from the compressed arrays (a node matrix has hundreds of
  // thousands of entries: no iterator or push_back per entry).
  const int64_t n = a.rows();
  const int32_t* outer = a.outerIndexPtr();
  const int32_t* inner = a.innerIndexPtr();
  const double* values = a.valuePtr();
  start_.assign(outer, outer + n + 1);
  const int64_t nnz = start_[n];
  bool exact = true;
  for (int64_t k = 0; k < nnz; ++k) {
    exact &= static_cast<double>(static_cast<float>(values[k])) == values[k];
  }
  narrow_ = cols_ <= 65536;
  exact_ = exact;
  if (narrow_) {
    col16_.resize(nnz);
    for (int64_t k = 0; k < nnz; ++k) col16_[k] = static_cast<uint16_t>(inner[k]);
  } else {
    col32_.assign(inner, inner + nnz);
  }
  if (exact) {
    val32_.resize(nnz);
    for (int64_t k = 0; k < nnz; ++k) val32_[k] = static_cast<float>(values[k]);
  } else {
    val64_.assign(values, values + nnz);
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
