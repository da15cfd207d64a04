// Picking (what a viewer needs for every tool): a ray against the current
// boundary surface, answered with the hit's material point and the control
// cell and control face that own it.
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "solver/mesh/pick.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

// Outward unit normal of a (possibly degenerate) quad from its diagonals.
Eigen::Vector3d QuadNormal(const std::array<int32_t, 4>& q, const Points& x) {
  const Eigen::Vector3d d1 = x.row(q[2]).transpose() - x.row(q[0]).transpose();
  const Eigen::Vector3d d2 = x.row(q[3]).transpose() - x.row(q[1]).transpose();
  Eigen::Vector3d n = d1.cross(d2);
  if (q[2] == q[3]) {  // triangle (a, b, c, c)
    n = (x.row(q[1]) - x.row(q[0])).transpose().cross((x.row(q[2]) - x.row(q[0])).transpose());
  }
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

// Outward unit normal of control face f seen from cell c (Newell's method).
Eigen::Vector3d ControlFaceNormal(const mesh::CellComplex& m, int32_t c, int32_t local,
                                  std::vector<int32_t>& loop) {
  m.CellFaceLoop(c, local, loop);
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  const Points& x = m.positions();
  for (size_t i = 0; i < loop.size(); ++i) {
    const Eigen::Vector3d a = x.row(loop[i]).transpose();
    const Eigen::Vector3d b = x.row(loop[(i + 1) % loop.size()]).transpose();
    n += a.cross(b);
  }
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : n;
}

}  // namespace

absl::StatusOr<std::optional<Solid::PickHit>> Solid::Pick(const Eigen::Vector3d& origin,
                                                          const Eigen::Vector3d& direction) const {
  const Impl& im = *impl_;
  const Points x = SurfacePositions();
  absl::StatusOr<mesh::PickHit> hit = mesh::PickQuads(surface_.quads, x, {origin, direction});
  if (absl::IsNotFound(hit.status())) return std::nullopt;
  if (!hit.ok()) return hit.status();

  PickHit out;
  out.quad = hit->quad;
  out.point = hit->point;
  out.distance = hit->distance;
  const std::array<int32_t, 4>& q = surface_.quads[out.quad];
  out.material_point = mesh::BilinearPoint(q, im.surface_rest, hit->s, hit->t);
  out.normal = QuadNormal(q, x);
  const std::vector<int32_t>& cc = d_.hierarchy.control_cell;
  const int32_t fine_cell = im.quad_cell[out.quad];
  out.control_cell = cc.empty() ? fine_cell : cc[fine_cell];

  // The control face: among the control cell's boundary faces, the one whose
  // outward normal is closest to the surface's rest normal at the hit (the
  // subdivision surface lies over the control face it descends from), ties
  // to the nearest centroid.
  const mesh::CellComplex& control = d_.control();
  const Eigen::Vector3d rest_normal = QuadNormal(q, im.surface_rest);
  const std::span<const int32_t> faces = control.cell_faces(out.control_cell);
  std::vector<int32_t> loop;
  double best = -std::numeric_limits<double>::infinity();
  double best_dist = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < faces.size(); ++k) {
    if (!control.face_is_boundary(faces[k])) continue;
    const double align = ControlFaceNormal(control, out.control_cell, static_cast<int32_t>(k), loop)
                             .dot(rest_normal);
    const double dist = (control.FaceCentroid(faces[k]) - out.material_point).norm();
    if (align > best + 1e-9 || (std::abs(align - best) <= 1e-9 && dist < best_dist)) {
      best = align;
      best_dist = dist;
      out.control_face = faces[k];
    }
  }
  return out;
}

}  // namespace dynsolid::solid
