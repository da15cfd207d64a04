#include "solver/mesh/boundary.h"

namespace dynsolid::mesh {

BoundarySurface ExtractBoundary(const CellComplex& complex, const Points* positions) {
  const Points& p = positions != nullptr ? *positions : complex.positions();
  BoundarySurface s;
  std::vector<int32_t> local(complex.num_vertices(), -1);
  for (int32_t f = 0; f < complex.num_faces(); ++f) {
    if (!complex.face_is_boundary(f)) continue;
    // Boundary loops are stored outward for their one cell.
    for (int32_t v : complex.face_vertices(f)) {
      if (local[v] < 0) {
        local[v] = static_cast<int32_t>(s.mesh_vertex.size());
        s.mesh_vertex.push_back(v);
      }
      s.faces.items.push_back(local[v]);
    }
    s.faces.offsets.push_back(static_cast<int32_t>(s.faces.items.size()));
    s.mesh_face.push_back(f);
  }
  s.positions.resize(static_cast<Eigen::Index>(s.mesh_vertex.size()), 3);
  for (size_t i = 0; i < s.mesh_vertex.size(); ++i) {
    s.positions.row(static_cast<Eigen::Index>(i)) = p.row(s.mesh_vertex[i]);
  }
  return s;
}

}  // namespace dynsolid::mesh
