#include "tests/sculpt/voxel_mesh.h"

#include <algorithm>
#include <map>

namespace dynsolid::sculpt::testing {

mesh::MeshInput Voxels(const std::vector<std::array<int, 3>>& voxels, double h) {
  // Lattice nodes keyed (k, j, i) so that map order is the vertex order.
  std::map<std::array<int, 3>, int32_t> nodes;
  for (const auto& v : voxels)
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) nodes[{v[2] + dz, v[1] + dy, v[0] + dx}] = 0;
  mesh::MeshInput input;
  input.vertices.resize(static_cast<Eigen::Index>(nodes.size()), 3);
  int32_t n = 0;
  for (auto& [key, id] : nodes) {
    id = n;
    input.vertices.row(n++) << h * key[2], h * key[1], h * key[0];
  }
  for (const auto& v : voxels) {
    auto c = [&](int dx, int dy, int dz) { return nodes.at({v[2] + dz, v[1] + dy, v[0] + dx}); };
    input.cells.push_back({
        {c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)},  // -z
        {c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)},  // +z
        {c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)},  // -y
        {c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)},  // +y
        {c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)},  // -x
        {c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)},  // +x
    });
  }
  input.origin = "voxels";
  return input;
}

mesh::MeshInput Block(int nx, int ny, int nz, double h) {
  std::vector<std::array<int, 3>> voxels;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) voxels.push_back({i, j, k});
  return Voxels(voxels, h);
}

int32_t FaceAt(const mesh::CellComplex& complex, const Eigen::Vector3d& centroid) {
  for (int32_t f = 0; f < complex.num_faces(); ++f) {
    if ((complex.FaceCentroid(f) - centroid).norm() < 1e-9) return f;
  }
  return -1;
}

int32_t BoundaryFaceAt(const mesh::CellComplex& complex, const Eigen::Vector3d& centroid) {
  const int32_t f = FaceAt(complex, centroid);
  return f >= 0 && complex.face_is_boundary(f) ? f : -1;
}

int64_t CountBoundaryFaces(const mesh::CellComplex& complex) {
  int64_t n = 0;
  for (int32_t f = 0; f < complex.num_faces(); ++f) n += complex.face_is_boundary(f) ? 1 : 0;
  return n;
}

}  // namespace dynsolid::sculpt::testing
