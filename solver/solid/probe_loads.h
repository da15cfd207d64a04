// The haptic probe's loads on the solid (solid.h "Haptic contact"): forces
// at points of the boundary surface, held as the control-space forces
// J_c^T f they give, non-zero only on the control points they touch. A part
// of Solid with its own state (docs/architecture.md "The solid's parts"):
// Solid turns a surface point into control weights; the loads keep, sum
// and patch.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "solver/mesh/points.h"

namespace dynsolid::solid {

class ProbeLoads {
 public:
  // A load: the control weights of its surface point and its force (N).
  using Load = std::pair<std::vector<std::pair<int32_t, double>>, Eigen::Vector3d>;

  bool active() const { return !rows_.empty(); }
  // #control x 3 once Set was called; zero off rows().
  const Points& force() const { return force_; }
  const std::vector<int32_t>& rows() const { return rows_; }

  // Replaces the loads with `loads` over nc control points (loads with a
  // zero force touch nothing). `carried`, when given, holds forces that
  // include the old loads: the change is patched into it, row by row.
  void Set(int64_t nc, const std::vector<Load>& loads, Points* carried);
  // out += the loads.
  void AddTo(Points& out) const {
    if (active()) out += force_;
  }
  // Their work over a move from p to p_next (constant forces: exact).
  double Work(const Points& p, const Points& p_next) const;
  // Drops the loads without touching any carried forces (after a restore,
  // whose carried forces have none).
  void Clear();

 private:
  Points force_;
  std::vector<int32_t> rows_;  // ascending
};

}  // namespace dynsolid::solid
