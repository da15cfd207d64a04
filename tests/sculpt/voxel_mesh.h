// Test meshes for sculpt tests: unions of unit-cube voxels on a lattice.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "solver/mesh/cell_complex.h"

namespace dynsolid::sculpt::testing {

// Hexahedral cells of edge `h` at lattice cells `voxels` (i, j, k); voxels
// that share lattice nodes share vertices. Vertices are numbered by lattice
// node in (k, j, i) order; cells in the order given.
mesh::MeshInput Voxels(const std::vector<std::array<int, 3>>& voxels, double h = 1.0);

// An nx x ny x nz block of voxels (i fastest).
mesh::MeshInput Block(int nx, int ny, int nz, double h = 1.0);

// The boundary face whose centroid is within 1e-9 of `centroid`, or -1.
int32_t BoundaryFaceAt(const mesh::CellComplex& complex, const Eigen::Vector3d& centroid);
// Any face (boundary or not) whose centroid is within 1e-9 of `centroid`, or -1.
int32_t FaceAt(const mesh::CellComplex& complex, const Eigen::Vector3d& centroid);

int64_t CountBoundaryFaces(const mesh::CellComplex& complex);

}  // namespace dynsolid::sculpt::testing
