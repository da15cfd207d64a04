// Ray picking on a quad surface (the level-L boundary, docs/model.md section 7).
//
// Quads are vertex loops (a, b, c, d) into `positions` (#V by 3, metres); a
// triangle is the degenerate quad (a, b, c, c). A quad's bilinear map is
//   B(s, t) = (1-s)(1-t) a + s(1-t) b + s t c + (1-s) t d,   (s, t) in [0,1]^2,
// so a caller can evaluate the same (s, t) on rest positions to get the
// material point under the cursor.
//
// Each quad is intersected as the triangles (a, b, c) and (a, c, d); the
// hit's (s, t) is then solved exactly from the bilinear map (Gauss-Newton
// from the triangle's guess, clamped to [0,1]^2), so for a planar quad
// B(s, t) equals the hit point to rounding. Brute force over quads with a
// per-quad bounding-box early-out: meant for a few thousand quads per pick.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "solver/mesh/points.h"

namespace dynsolid::mesh {

struct Ray {
  Eigen::Vector3d origin;     // metres
  Eigen::Vector3d direction;  // any non-zero finite length
};

struct PickHit {
  int32_t quad = -1;        // index into the quads
  Eigen::Vector3d point;    // origin + distance * direction / |direction|, metres
  double distance = 0.0;    // along the ray from its origin, metres (> 0)
  double s = 0.0, t = 0.0;  // bilinear parameters of the hit in the quad
};

// The nearest hit strictly in front of the origin (ties: lowest quad index).
// InvalidArgument names `ray.origin` / `ray.direction` when non-finite or a
// zero direction, or a quad with a vertex out of range; NotFound
// "ray misses the surface" when nothing is hit.
absl::StatusOr<PickHit> PickQuads(const std::vector<std::array<int32_t, 4>>& quads,
                                  const Points& positions, const Ray& ray);

// B(s, t) on `positions` for one quad (see the header comment).
Eigen::Vector3d BilinearPoint(const std::array<int32_t, 4>& quad, const Points& positions, double s,
                              double t);

}  // namespace dynsolid::mesh
