// Internal: the linear volume cells that mesh files hold, and their faces
// as loops oriented outward (right-hand normal pointing out of the cell).
//
// Node order is Gmsh's (gmsh.info/doc, "Node ordering"), which for these
// four shapes is also VTK's except for the wedge:
//   tetrahedron  0 1 2 3        (0,1,2) turns counter-clockwise seen from 3
//   hexahedron   0-3 bottom loop, 4-7 above 0-3, bottom loop
//                counter-clockwise seen from the top
//   prism        0 1 2 bottom triangle, 3 4 5 above them; (0,1,2)
//                counter-clockwise seen from the top (VTK_WEDGE is the
//                mirror: its (0,1,2) turns the other way, see
//                VtkWedgeToGmshPrism)
//   pyramid      0-3 base loop counter-clockwise seen from the apex 4
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "solver/mesh/points.h"

namespace dynsolid::io::internal {

enum class Shape : uint8_t { kTetrahedron, kHexahedron, kPrism, kPyramid };

inline constexpr int NumNodes(Shape s) {
  switch (s) {
    case Shape::kTetrahedron:
      return 4;
    case Shape::kHexahedron:
      return 8;
    case Shape::kPrism:
      return 6;
    case Shape::kPyramid:
      return 5;
  }
  return 0;
}

const char* ShapeName(Shape s);

// The outward faces of a cell whose `nodes` (mesh vertex ids, NumNodes(shape)
// of them) are in the order above. Returns the face loops.
std::vector<std::vector<int32_t>> CellFaces(Shape shape, std::span<const int32_t> nodes);

// VTK_WEDGE (13) order -> Gmsh prism order: swaps 1<->2 and 4<->5.
inline std::array<int32_t, 6> VtkWedgeToGmshPrism(std::span<const int32_t> w) {
  return {w[0], w[2], w[1], w[3], w[5], w[4]};
}

// VTK_VOXEL (11) order (x fastest, then y, then z) -> hexahedron order.
inline std::array<int32_t, 8> VtkVoxelToHexahedron(std::span<const int32_t> v) {
  return {v[0], v[1], v[3], v[2], v[4], v[5], v[7], v[6]};
}

// Signed volume enclosed by `loops` over `points` (#P by 3), by the
// divergence theorem with each loop fanned from its centroid: positive when
// the loops are outward. Indices must be valid.
double SignedVolume(const Points& points, const std::vector<std::vector<int32_t>>& loops);

}  // namespace dynsolid::io::internal
