#include "solver/models/measure.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <Eigen/Geometry>

namespace dynsolid::models {

void DeformationMeasure::AddEdge(int32_t i, int32_t j, const Points& rest) {
  edges_.push_back({i, j, (rest.row(j) - rest.row(i)).norm()});
}

void DeformationMeasure::AddCorner(int32_t n, int32_t a, int32_t b, const Points& rest) {
  const Eigen::Vector3d ra = rest.row(a) - rest.row(n);
  const Eigen::Vector3d rb = rest.row(b) - rest.row(n);
  const double la = ra.norm(), lb = rb.norm();
  if (la <= 0 || lb <= 0) return;
  corners_.push_back({n, a, b, ra.dot(rb) / (la * lb), ra.cross(rb).norm() / (la * lb)});
}

DeformationMeasure::DeformationMeasure(const mesh::CellComplex& mesh,
                                       const fem::ElementSet& elements, const Points& rest) {
  edges_.reserve(mesh.num_edges());
  for (int32_t e = 0; e < mesh.num_edges(); ++e) {
    const auto& ev = mesh.edge_vertices(e);
    AddEdge(ev[0], ev[1], rest);
  }
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const auto loop = mesh.face_vertices(f);
    const size_t k = loop.size();
    for (size_t i = 0; i < k; ++i) {
      AddCorner(loop[i], loop[(i + k - 1) % k], loop[(i + 1) % k], rest);
    }
  }
  // Pyramid elements: centre-to-vertex edges and the side triangles, once each.
  for (int32_t v = 0; v < elements.num_virtual_nodes; ++v) {
    const int32_t apex = elements.num_mesh_vertices + v;
    for (int32_t x : mesh.cell_vertices(elements.virtual_node_cell[v])) AddEdge(apex, x, rest);
  }
  std::set<std::array<int32_t, 3>> triangles;
  for (int32_t p = 0; p < elements.num_pyramid(); ++p) {
    const int32_t* q = &elements.pyramid_nodes[5 * p];
    for (int s = 0; s < 4; ++s) {
      const int32_t a = q[s], b = q[(s + 1) % 4];
      if (a == b) continue;  // degenerate base side (a triangle face)
      std::array<int32_t, 3> key{std::min(a, b), std::max(a, b), q[4]};
      if (!triangles.insert(key).second) continue;
      AddCorner(q[4], a, b, rest);
      AddCorner(a, b, q[4], rest);
      AddCorner(b, q[4], a, rest);
    }
  }
}

namespace {

// A corner's current geometry and the rotation that restores its angle:
// with phi = (theta - theta0) / 2, C = cos(phi), S = sin(phi), rotating a by
// +phi and b by -phi about n gives delta_a = alpha ra - beta la b^ and
// delta_b = alpha rb - beta lb a^, alpha = 1 - C + c S / s, beta = S / s
// (c, s the cosine and sine of the current angle).
struct CornerState {
  Eigen::Vector3d ra, rb, ah, bh;
  double la, lb, c, s, cap_c, cap_s, alpha, beta;
};

// False for a degenerate corner (a zero side, collinear sides, or an angle
// half a turn from its rest value): it contributes nothing.
inline bool EvaluateCorner(const Points& d, int32_t n, int32_t a, int32_t b, double cos0,
                           double sin0, CornerState& k) {
  k.ra = d.row(a) - d.row(n);
  k.rb = d.row(b) - d.row(n);
  k.la = k.ra.norm();
  k.lb = k.rb.norm();
  if (k.la <= 0 || k.lb <= 0) return false;
  k.ah = k.ra / k.la;
  k.bh = k.rb / k.lb;
  k.c = k.ah.dot(k.bh);
  k.s = k.ah.cross(k.bh).norm();
  if (k.s <= 1e-300) return false;
  // phi in (-pi/2, pi/2) by half-angle formulas.
  const double cos_d = k.c * cos0 + k.s * sin0;
  const double sin_d = k.s * cos0 - k.c * sin0;
  k.cap_c = std::sqrt(std::max(0.0, 0.5 * (1.0 + cos_d)));
  if (k.cap_c < 1e-12) return false;
  k.cap_s = sin_d / (2.0 * k.cap_c);
  k.beta = k.cap_s / k.s;
  k.alpha = 1.0 - k.cap_c + k.c * k.beta;
  return true;
}

}  // namespace

void DeformationMeasure::ApplyPart(const Points& d, int k, int parts, Points& delta) const {
  delta.setZero(d.rows(), 3);
  const size_t ne = edges_.size(), nk = corners_.size();
  for (size_t i = ne * k / parts; i < ne * (k + 1) / parts; ++i) {
    const Edge& e = edges_[i];
    const Eigen::Vector3d r = d.row(e.j) - d.row(e.i);
    const double l = r.norm();
    if (l <= 0) continue;
    const Eigen::Vector3d s = (0.5 * (l - e.rest_length) / l) * r;
    delta.row(e.i) -= s.transpose();
    delta.row(e.j) += s.transpose();
  }
  CornerState g;
  for (size_t i = nk * k / parts; i < nk * (k + 1) / parts; ++i) {
    const Corner& c = corners_[i];
    if (!EvaluateCorner(d, c.n, c.a, c.b, c.cos0, c.sin0, g)) continue;
    delta.row(c.a) += (g.alpha * g.ra - (g.beta * g.la) * g.bh).transpose();
    delta.row(c.b) += (g.alpha * g.rb - (g.beta * g.lb) * g.ah).transpose();
  }
}

}  // namespace dynsolid::models

namespace dynsolid::models {

// Edge (i, j): c = 1/2 (1 - l0 / l) r with r = d_j - d_i adds to delta_j and
// subtracts from delta_i, so d/dr of (y_j - y_i) . c is
// J (y_j - y_i) with J = 1/2 [(1 - l0/l) I + (l0 / l^3) r r^T].
//
// Corner (n; a, b): with ra = a - n, rb = b - n, c = cos(theta),
// s = sin(theta), phi = (theta - theta0)/2, C = cos(phi), S = sin(phi), the
// rotations give delta_a = alpha ra - beta la b^, delta_b = alpha rb - beta lb a^
// with alpha = 1 - C + c S / s and beta = S / s. For F = ya.delta_a + yb.delta_b
// = alpha P - beta Q (P = ya.ra + yb.rb, Q = la ya.b^ + lb yb.a^) and
// dtheta/dra = -ta / la, dtheta/drb = -tb / lb (ta, tb the in-plane unit
// vectors perpendicular to a^ and b^ towards each other):
//   dF/dra = (P alpha' - Q beta') (-ta / la) + alpha ya
//            - beta [(ya.b^) a^ + (lb / la)(yb - (yb.a^) a^)],
// and symmetrically for rb; n gets minus both.
void DeformationMeasure::ApplyTransposePart(const Points& d, const Points& y, int k, int parts,
                                            Points& out) const {
  out.setZero(d.rows(), 3);
  const size_t ne = edges_.size(), nk = corners_.size();
  for (size_t i = ne * k / parts; i < ne * (k + 1) / parts; ++i) {
    const Edge& e = edges_[i];
    const Eigen::Vector3d r = d.row(e.j) - d.row(e.i);
    const double l = r.norm();
    if (l <= 0) continue;
    const Eigen::Vector3d dy = (y.row(e.j) - y.row(e.i)).transpose();
    const Eigen::Vector3d w =
        0.5 * ((1.0 - e.rest_length / l) * dy + (e.rest_length / (l * l * l)) * r.dot(dy) * r);
    out.row(e.j) += w.transpose();
    out.row(e.i) -= w.transpose();
  }
  CornerState g;
  for (size_t i = nk * k / parts; i < nk * (k + 1) / parts; ++i) {
    const Corner& cn = corners_[i];
    if (!EvaluateCorner(d, cn.n, cn.a, cn.b, cn.cos0, cn.sin0, g)) continue;
    const Eigen::Vector3d &ra = g.ra, &rb = g.rb, &ah = g.ah, &bh = g.bh;
    const double la = g.la, lb = g.lb, c = g.c, s = g.s, C = g.cap_c, S = g.cap_s;
    const double alpha = g.alpha, beta = g.beta;
    const double dalpha = -0.5 * S + c * C / (2.0 * s) - c * c * S / (s * s);
    const double dbeta = C / (2.0 * s) - S * c / (s * s);
    const Eigen::Vector3d ya = y.row(cn.a).transpose(), yb = y.row(cn.b).transpose();
    const double p = ya.dot(ra) + yb.dot(rb);
    const double yab = ya.dot(bh), yba = yb.dot(ah);
    const double q = la * yab + lb * yba;
    const double dtheta_coef = p * dalpha - q * dbeta;
    const Eigen::Vector3d ta = (bh - c * ah) / s, tb = (ah - c * bh) / s;
    const Eigen::Vector3d ga = dtheta_coef * (-ta / la) + alpha * ya -
                               beta * (yab * ah + (lb / la) * (yb - yba * ah));
    const Eigen::Vector3d gb = dtheta_coef * (-tb / lb) + alpha * yb -
                               beta * (yba * bh + (la / lb) * (ya - yab * bh));
    out.row(cn.a) += ga.transpose();
    out.row(cn.b) += gb.transpose();
    out.row(cn.n) -= (ga + gb).transpose();
  }
}

}  // namespace dynsolid::models
