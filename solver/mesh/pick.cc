// Ray picking on quads: Moller-Trumbore per triangle, then an inverse
// bilinear solve for (s, t).
#include "solver/mesh/pick.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"

namespace dynsolid::mesh {
namespace {

using Vec = Eigen::Vector3d;

Vec Row(const Points& p, int32_t v) { return p.row(v).transpose(); }

// Distance along unit `dir` to triangle (p0, p1, p2), or +inf; (u, v) the
// barycentric weights of p1 and p2 at the hit.
double HitTriangle(const Vec& origin, const Vec& dir, const Vec& p0, const Vec& p1, const Vec& p2,
                   double* u, double* v) {
  const Vec e1 = p1 - p0, e2 = p2 - p0;
  const Vec q = dir.cross(e2);
  const double det = e1.dot(q);
  const double scale = e1.norm() * e2.norm();
  if (!(std::abs(det) > 1e-14 * scale)) return std::numeric_limits<double>::infinity();
  const double inv = 1.0 / det;
  const Vec r = origin - p0;
  *u = r.dot(q) * inv;
  const Vec w = r.cross(e1);
  *v = dir.dot(w) * inv;
  const double eps = 1e-12;
  if (*u < -eps || *v < -eps || *u + *v > 1.0 + eps) return std::numeric_limits<double>::infinity();
  const double dist = e2.dot(w) * inv;
  return dist > 0.0 ? dist : std::numeric_limits<double>::infinity();
}

// Does the ray (unit dir, inverse components inv) meet the box within `limit`?
bool HitsBox(const Vec& origin, const Vec& inv, const Vec& lo, const Vec& hi, double limit) {
  double t0 = 0.0, t1 = limit;
  for (int k = 0; k < 3; ++k) {
    double a = (lo[k] - origin[k]) * inv[k], b = (hi[k] - origin[k]) * inv[k];
    if (std::isnan(a) || std::isnan(b)) {  // direction 0 along k and origin on a slab plane
      if (origin[k] < lo[k] || origin[k] > hi[k]) return false;
      continue;
    }
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a);
    t1 = std::min(t1, b);
    if (t0 > t1) return false;
  }
  return true;
}

// (s, t) minimising |B(s, t) - x| from the guess, by Gauss-Newton on the
// 2x2 normal equations, clamped to the unit square.
void InverseBilinear(const Vec& a, const Vec& b, const Vec& c, const Vec& d, const Vec& x,
                     double* s, double* t) {
  for (int it = 0; it < 20; ++it) {
    const Vec bst = (1 - *s) * (1 - *t) * a + *s * (1 - *t) * b + *s * *t * c + (1 - *s) * *t * d;
    const Vec r = bst - x;
    const Vec ds = (1 - *t) * (b - a) + *t * (c - d);
    const Vec dt = (1 - *s) * (d - a) + *s * (c - b);
    const double m00 = ds.dot(ds), m01 = ds.dot(dt), m11 = dt.dot(dt);
    const double det = m00 * m11 - m01 * m01;
    if (!(std::abs(det) > 1e-30 * (m00 * m11 + 1e-300))) return;  // degenerate: keep the guess
    const double g0 = ds.dot(r), g1 = dt.dot(r);
    const double step_s = (m11 * g0 - m01 * g1) / det;
    const double step_t = (m00 * g1 - m01 * g0) / det;
    *s = std::clamp(*s - step_s, 0.0, 1.0);
    *t = std::clamp(*t - step_t, 0.0, 1.0);
    if (std::abs(step_s) + std::abs(step_t) < 1e-15) return;
  }
}

}  // namespace

Eigen::Vector3d BilinearPoint(const std::array<int32_t, 4>& q, const Points& p, double s,
                              double t) {
  return (1 - s) * (1 - t) * Row(p, q[0]) + s * (1 - t) * Row(p, q[1]) + s * t * Row(p, q[2]) +
         (1 - s) * t * Row(p, q[3]);
}

absl::StatusOr<PickHit> PickQuads(const std::vector<std::array<int32_t, 4>>& quads,
                                  const Points& positions, const Ray& ray) {
  if (!ray.origin.allFinite()) {
    return absl::InvalidArgumentError(absl::StrCat("ray.origin: (", ray.origin.x(), ", ",
                                                   ray.origin.y(), ", ", ray.origin.z(),
                                                   ") is not finite"));
  }
  const double len = ray.direction.norm();
  if (!ray.direction.allFinite() || !(len > 0.0) || !std::isfinite(len)) {
    return absl::InvalidArgumentError(absl::StrCat("ray.direction: (", ray.direction.x(), ", ",
                                                   ray.direction.y(), ", ", ray.direction.z(),
                                                   ") must be non-zero and finite"));
  }
  const int32_t nv = static_cast<int32_t>(positions.rows());
  for (size_t i = 0; i < quads.size(); ++i) {
    for (int32_t v : quads[i]) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(
            absl::StrCat("quads[", i, "]: vertex ", v, " is out of range [0, ", nv, ")"));
      }
    }
  }
  const Vec dir = ray.direction / len;
  const Vec inv = dir.cwiseInverse();
  PickHit best;
  best.distance = std::numeric_limits<double>::infinity();
  double best_s = 0.0, best_t = 0.0;
  for (size_t i = 0; i < quads.size(); ++i) {
    const auto& q = quads[i];
    const Vec a = Row(positions, q[0]), b = Row(positions, q[1]), c = Row(positions, q[2]),
              d = Row(positions, q[3]);
    const Vec lo = a.cwiseMin(b).cwiseMin(c).cwiseMin(d);
    const Vec hi = a.cwiseMax(b).cwiseMax(c).cwiseMax(d);
    const Vec pad = Vec::Constant(1e-12 * (hi - lo).norm());
    if (!HitsBox(ray.origin, inv, lo - pad, hi + pad, best.distance)) continue;
    double u = 0.0, v = 0.0;
    // Triangle (a, b, c): (s, t) = (u + v, v); triangle (a, c, d): (u, u + v).
    double dist = HitTriangle(ray.origin, dir, a, b, c, &u, &v);
    if (dist < best.distance) {
      best.distance = dist;
      best.quad = static_cast<int32_t>(i);
      best_s = u + v;
      best_t = v;
    }
    dist = HitTriangle(ray.origin, dir, a, c, d, &u, &v);
    if (dist < best.distance) {
      best.distance = dist;
      best.quad = static_cast<int32_t>(i);
      best_s = u;
      best_t = u + v;
    }
  }
  if (best.quad < 0) return absl::NotFoundError("ray misses the surface");
  best.point = ray.origin + best.distance * dir;
  best.s = std::clamp(best_s, 0.0, 1.0);
  best.t = std::clamp(best_t, 0.0, 1.0);
  const auto& q = quads[best.quad];
  InverseBilinear(Row(positions, q[0]), Row(positions, q[1]), Row(positions, q[2]),
                  Row(positions, q[3]), best.point, &best.s, &best.t);
  return best;
}

}  // namespace dynsolid::mesh
