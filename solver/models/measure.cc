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
  for (size_t i = nk * k / parts; i < nk * (k + 1) / parts; ++i) {
    const Corner& c = corners_[i];
    const Eigen::Vector3d ra = d.row(c.a) - d.row(c.n);
    const Eigen::Vector3d rb = d.row(c.b) - d.row(c.n);
    const Eigen::Vector3d axis = ra.cross(rb);
    const double cross = axis.norm();
    const double la = ra.norm(), lb = rb.norm();
    if (cross <= 1e-300 || la <= 0 || lb <= 0) continue;  // collinear: no plane
    const double cos_t = ra.dot(rb) / (la * lb), sin_t = cross / (la * lb);
    // phi = (theta - theta0) / 2 in (-pi/2, pi/2), by half-angle formulas.
    const double cos_d = cos_t * c.cos0 + sin_t * c.sin0;
    const double sin_d = sin_t * c.cos0 - cos_t * c.sin0;
    const double cos_phi = std::sqrt(std::max(0.0, 0.5 * (1.0 + cos_d)));
    if (cos_phi < 1e-12) continue;
    const double sin_phi = sin_d / (2.0 * cos_phi);
    const Eigen::Vector3d k = axis / cross;
    // a' - n = ra cos(phi) + (k x ra) sin(phi); b' - n = rb cos(phi) - (k x rb) sin(phi).
    const Eigen::Vector3d da = ra * (1.0 - cos_phi) - k.cross(ra) * sin_phi;
    const Eigen::Vector3d db = rb * (1.0 - cos_phi) + k.cross(rb) * sin_phi;
    delta.row(c.a) += da.transpose();
    delta.row(c.b) += db.transpose();
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
  for (size_t i = nk * k / parts; i < nk * (k + 1) / parts; ++i) {
    const Corner& cn = corners_[i];
    const Eigen::Vector3d ra = d.row(cn.a) - d.row(cn.n);
    const Eigen::Vector3d rb = d.row(cn.b) - d.row(cn.n);
    const double la = ra.norm(), lb = rb.norm();
    if (la <= 0 || lb <= 0) continue;
    const Eigen::Vector3d ah = ra / la, bh = rb / lb;
    const double c = ah.dot(bh);
    const double s = ah.cross(bh).norm();
    if (s <= 1e-300) continue;
    const double cos_d = c * cn.cos0 + s * cn.sin0;
    const double sin_d = s * cn.cos0 - c * cn.sin0;
    const double C = std::sqrt(std::max(0.0, 0.5 * (1.0 + cos_d)));
    if (C < 1e-12) continue;
    const double S = sin_d / (2.0 * C);
    const double alpha = 1.0 - C + c * S / s;
    const double beta = S / s;
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
