// Follower pressure on the boundary surface: the pascals each surface quad
// carries (the sum of the load set's pressures that select it) and the
// consistent nodal forces they give at the current positions. A part of
// Solid with its own state (docs/architecture.md "The solid's parts"): it
// knows the surface's quads and their rows of the node matrix, nothing of
// the material or the integrator.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "solver/common/sparse_matrix.h"
#include "solver/mesh/points.h"
#include "solver/solid/load_set.h"

namespace dynsolid::solid {

class SurfacePressure {
 public:
  // The per-quad pascals of `pressures` over `quads` (outward, over the
  // surface vertices) whose vertices' control rows are `surface_rows`
  // (#surface vertices x #control points).
  void Rebuild(const std::vector<std::array<int32_t, 4>>& quads, const SparseMatrix& surface_rows,
               const std::vector<LoadSet::PressureLoad>& pressures);
  // No quad carries a non-zero pressure.
  bool empty() const { return pressed_.empty(); }
  // out = the control forces of the pressure at control positions p
  // (#control x 3), zero when empty().
  void Forces(const Points& p, Points& out);

 private:
  std::vector<double> quad_pascals_;  // per surface quad, Pa
  // The quads with a non-zero pressure, their corners numbered among the
  // pressed quads' vertices (ascending), and those vertices' rows.
  std::vector<int32_t> pressed_;
  std::vector<std::array<int32_t, 4>> pressed_corners_;
  SparseMatrix pressed_rows_;
  Points surf_x_, surf_f_;  // the pressed vertices' positions and forces
};

}  // namespace dynsolid::solid
