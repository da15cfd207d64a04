// Tiny hand-made control meshes for unit tests (header-only, test code).
#pragma once

#include <array>
#include <vector>

#include "solver/mesh/cell_complex.h"

namespace dynsolid::testing {

// Outward faces of a hexahedron given its corners in VTK order
// (0-3 bottom, counter-clockwise seen from above; 4-7 above them).
inline std::vector<std::vector<int32_t>> HexFaces(const std::array<int32_t, 8>& h) {
  return {{h[0], h[3], h[2], h[1]}, {h[4], h[5], h[6], h[7]}, {h[0], h[1], h[5], h[4]},
          {h[1], h[2], h[6], h[5]}, {h[2], h[3], h[7], h[6]}, {h[3], h[0], h[4], h[7]}};
}

// nx x ny x nz unit cubes; vertex (i, j, k) has index i + (nx+1) (j + (ny+1) k).
inline mesh::MeshInput Grid(int nx, int ny, int nz, double h = 1.0) {
  mesh::MeshInput in;
  in.origin = "test grid";
  auto id = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };
  in.vertices.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) in.vertices.row(id(i, j, k)) << i * h, j * h, k * h;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        in.cells.push_back(HexFaces({id(i, j, k), id(i + 1, j, k), id(i + 1, j + 1, k),
                                     id(i, j + 1, k), id(i, j, k + 1), id(i + 1, j, k + 1),
                                     id(i + 1, j + 1, k + 1), id(i, j + 1, k + 1)}));
  return in;
}

// A square pyramid: base [0,1]^2 at z = 0, apex (0.5, 0.5, 1).
inline mesh::MeshInput Pyramid() {
  mesh::MeshInput in;
  in.origin = "test pyramid";
  in.vertices.resize(5, 3);
  in.vertices << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0.5, 0.5, 1;
  in.cells.push_back({{0, 3, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}});
  return in;
}

// A tetrahedron with positive orientation.
inline mesh::MeshInput Tetrahedron() {
  mesh::MeshInput in;
  in.origin = "test tetrahedron";
  in.vertices.resize(4, 3);
  in.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  in.cells.push_back({{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}});
  return in;
}

}  // namespace dynsolid::testing
