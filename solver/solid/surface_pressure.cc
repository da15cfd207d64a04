#include "solver/solid/surface_pressure.h"

#include <algorithm>
#include <cmath>

namespace dynsolid::solid {

void SurfacePressure::Rebuild(const std::vector<std::array<int32_t, 4>>& quads,
                              const SparseMatrix& surface_rows,
                              const std::vector<LoadSet::PressureLoad>& pressures) {
  quad_pascals_.assign(quads.size(), 0.0);
  for (const LoadSet::PressureLoad& load : pressures) {
    for (int32_t q : load.quads) quad_pascals_[q] += load.msg.pascals();
  }
  pressed_.clear();
  for (size_t q = 0; q < quad_pascals_.size(); ++q) {
    if (quad_pascals_[q] != 0) pressed_.push_back(static_cast<int32_t>(q));
  }
  // The pressed quads' vertices (ascending) and their rows of S: the step
  // evaluates the pressure there, not over the whole surface.
  std::vector<int32_t> vertices;
  for (int32_t q : pressed_) {
    for (int32_t v : quads[q]) vertices.push_back(v);
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  pressed_corners_.clear();
  for (int32_t q : pressed_) {
    std::array<int32_t, 4> local;
    for (int k = 0; k < 4; ++k) {
      local[k] = static_cast<int32_t>(
          std::lower_bound(vertices.begin(), vertices.end(), quads[q][k]) - vertices.begin());
    }
    pressed_corners_.push_back(local);
  }
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (size_t i = 0; i < vertices.size(); ++i) {
    for (SparseMatrix::InnerIterator it(surface_rows, vertices[i]); it; ++it) {
      t.emplace_back(static_cast<int32_t>(i), static_cast<int32_t>(it.col()), it.value());
    }
  }
  pressed_rows_.resize(static_cast<Eigen::Index>(vertices.size()), surface_rows.cols());
  pressed_rows_.setFromTriplets(t.begin(), t.end());
  pressed_rows_.makeCompressed();
  const int64_t ns = static_cast<int64_t>(vertices.size());
  surf_x_.setZero(ns, 3);
  surf_f_.setZero(ns, 3);
}

// out = S^T f_s with f_s the consistent nodal forces of the pressure on the
// surface quads at the current surface positions x_s = S p (S: the surface
// rows of A). Each quad is a bilinear patch x(u, v) = sum N_i x_i over its
// loop (a boundary face of a linear or pyramid element, so the element's own
// interpolation): f_i = P int N_i (x_u x x_v) du dv, exact with 2 x 2 Gauss
// points (the integrand has degree 2 in u and in v). x_u x x_v follows the
// outward loop, so P > 0 pushes outward. The forces sum to P times the
// quad's vector area; over a closed surface to zero.
void SurfacePressure::Forces(const Points& p, Points& out) {
  if (pressed_.empty()) {
    out.setZero(p.rows(), 3);
    return;
  }
  surf_x_.noalias() = pressed_rows_ * p;
  surf_f_.setZero();
  const double g0 = 0.5 - 0.5 / std::sqrt(3.0), g1 = 0.5 + 0.5 / std::sqrt(3.0);
  const double gp[2] = {g0, g1};
  for (size_t j = 0; j < pressed_.size(); ++j) {
    const int32_t q = pressed_[j];
    const std::array<int32_t, 4>& v = pressed_corners_[j];
    const Eigen::Vector3d x0 = surf_x_.row(v[0]).transpose(), x1 = surf_x_.row(v[1]).transpose(),
                          x2 = surf_x_.row(v[2]).transpose(), x3 = surf_x_.row(v[3]).transpose();
    Eigen::Vector3d fn[4] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                             Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
    for (double u : gp) {
      for (double w : gp) {
        // N0 = (1-u)(1-w), N1 = u(1-w), N2 = u w, N3 = (1-u) w.
        const Eigen::Vector3d xu = (1 - w) * (x1 - x0) + w * (x2 - x3);
        const Eigen::Vector3d xw = (1 - u) * (x3 - x0) + u * (x2 - x1);
        const Eigen::Vector3d n = 0.25 * xu.cross(xw);  // Gauss weights 1/2 x 1/2
        fn[0] += ((1 - u) * (1 - w)) * n;
        fn[1] += (u * (1 - w)) * n;
        fn[2] += (u * w) * n;
        fn[3] += ((1 - u) * w) * n;
      }
    }
    const double pa = quad_pascals_[q];
    for (int k = 0; k < 4; ++k) surf_f_.row(v[k]) += (pa * fn[k]).transpose();
  }
  out.noalias() = pressed_rows_.transpose() * surf_f_;
}

}  // namespace dynsolid::solid
