// Private to solver/solid: a MaterialSampler that hands out material
// samples by their place in the layout (shared by painting and restore).
#pragma once

#include <functional>

#include <Eigen/Dense>

#include "solver/fem/shape.h"
#include "solver/models/element_blocks.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {

// A MaterialSampler for BuildElementLayout that hands out samples by their
// place (kind, element, quadrature point) rather than by position:
// BuildElementLayout samples in exactly that order (kinds 0..2, elements in
// block order, points in table order). `fn(kind, e, q, x, cell)` gives the
// sample. Each call's position is checked against the expected sample's
// (the same expression as BuildElementLayout's), so a change of that order
// is caught (ok() false) instead of silently scrambling materials.
class OrderedSampler {
 public:
  using Fn = std::function<models::MaterialPoint(int kind, int32_t e, int q,
                                                 const Eigen::Vector3d& x, int32_t cell)>;
  OrderedSampler(const models::ElementLayout& layout, const Points& rest_nodes, Fn fn)
      : layout_(layout), rest_(rest_nodes), fn_(std::move(fn)) {
    Skip();
  }
  models::MaterialPoint operator()(const Eigen::Vector3d& x, int32_t cell) {
    if (kind_ >= 3) {
      ok_ = false;
      return {};
    }
    const models::ElementBlock& block = layout_.blocks[kind_];
    const fem::KindTable& table = layout_.tables[kind_];
    const int n = block.nodes;
    const int32_t* ids = block.element_nodes(e_);
    xe_.resize(n, 3);
    for (int i = 0; i < n; ++i) xe_.row(i) = rest_.row(ids[i]);
    const Eigen::Map<const Eigen::Matrix<double, 1, Eigen::Dynamic>> nq(table.N(q_), n);
    const Eigen::Vector3d expected = (nq * xe_).transpose();
    // The same point to rounding (the layout builder and this check may
    // fuse multiply-adds differently).
    if ((expected - x).norm() > 1e-12 * (1.0 + x.norm())) ok_ = false;
    const models::MaterialPoint m = fn_(kind_, e_, q_, x, cell);
    if (++q_ == table.points) {
      q_ = 0;
      ++e_;
      Skip();
    }
    return m;
  }
  // Every sample was handed out, in order.
  bool ok() const { return ok_ && kind_ == 3; }

 private:
  void Skip() {
    while (kind_ < 3 && e_ >= layout_.blocks[kind_].size()) {
      ++kind_;
      e_ = 0;
    }
  }
  const models::ElementLayout& layout_;
  const Points& rest_;
  Fn fn_;
  int kind_ = 0;
  int32_t e_ = 0;
  int q_ = 0;
  bool ok_ = true;
  fem::NodeMatrixX3 xe_;
};

}  // namespace dynsolid::solid
