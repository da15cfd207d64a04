// The local-frame deformation measure R (MODEL.md 4a): a per-node vector
// delta built only from changes of edge lengths and face corner angles, so
// it is blind to rigid motion.
//  - stretch, per edge (i, j): delta_i -= (l - l0)/2 e_ij,
//    delta_j += (l - l0)/2 e_ij;
//  - shear, per face corner (n; a, b): rotate a by +(theta - theta0)/2 and
//    b by -(theta - theta0)/2 about n along (a - n) x (b - n), which brings
//    the angle back to theta0; delta_a += a - a', delta_b += b - b'.
// Edges and faces are those of the level-L mesh plus, for pyramid
// elements, the edges from the virtual centre node to its cell's vertices
// and the triangles it spans with the cell's face edges.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "solver/fem/element_set.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::models {

class DeformationMeasure {
 public:
  DeformationMeasure() = default;
  DeformationMeasure(const mesh::CellComplex& mesh, const fem::ElementSet& elements,
                     const Points& rest);

  // delta (#nodes by 3) for node positions d. Overwrites delta.
  void Apply(const Points& d, Points& delta) const { ApplyPart(d, 0, 1, delta); }

  // Part k of `parts` (edges and corners split in fixed ranges): summing the
  // parts' deltas in order gives Apply's result (to rounding of the sum).
  void ApplyPart(const Points& d, int k, int parts, Points& delta) const;

  // The transpose of the measure's Jacobian applied to y (#nodes by 3):
  // out = (d delta / d d)^T y, so that for an energy E(delta), the force is
  // dE/dd = ApplyTranspose(dE/d delta). Part k of `parts` as in ApplyPart.
  void ApplyTransposePart(const Points& d, const Points& y, int k, int parts, Points& out) const;

  int64_t num_edges() const { return static_cast<int64_t>(edges_.size()); }
  int64_t num_corners() const { return static_cast<int64_t>(corners_.size()); }

 private:
  struct Edge {
    int32_t i, j;
    double rest_length;
  };
  struct Corner {
    int32_t n, a, b;
    double cos0, sin0;  // of the rest angle
  };
  void AddEdge(int32_t i, int32_t j, const Points& rest);
  void AddCorner(int32_t n, int32_t a, int32_t b, const Points& rest);

  std::vector<Edge> edges_;
  std::vector<Corner> corners_;
};

}  // namespace dynsolid::models
