// Test helpers: checks of a mesh::MeshInput that do not rely on
// mesh::CellComplex (an independent reference for the generators), and a
// summary of a built CellComplex.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::scene::testing {

// Checks, without CellComplex:
//  - every index is in range, no loop repeats a vertex, every vertex is used;
//  - every cell is closed (each directed edge of its loops has its reverse
//    in another loop of the same cell);
//  - every face (vertex set) lies in one or two cells, and in two with
//    opposite loops;
//  - every cell encloses positive volume (divergence theorem over its loops,
//    so the loops are outward).
// Returns InvalidArgument naming the first violation.
absl::Status CheckMeshInput(const mesh::MeshInput& input);

// Signed volume enclosed by cell c's loops (triangle fans), m^3.
double CellVolume(const mesh::MeshInput& input, int32_t c);

// Number of connected components of cells joined through shared faces.
int32_t CountComponents(const mesh::MeshInput& input);

}  // namespace dynsolid::scene::testing
