// Boundary representation (docs/model.md section 7): the faces with one cell,
// as a polygon mesh with outward loops, for rendering and export.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "solver/mesh/cell_complex.h"

namespace dynsolid::mesh {

// A per-vertex field on the boundary surface: `components` values per vertex.
struct VertexField {
  std::string name;
  int components = 1;
  std::vector<double> values;  // #boundary vertices * components
};

struct BoundarySurface {
  Points positions;                     // #B by 3
  std::vector<int32_t> mesh_vertex;     // boundary vertex -> vertex of the complex
  Csr faces;                            // loops over boundary vertices, outward
  std::vector<int32_t> mesh_face;       // boundary face -> face of the complex
  std::vector<VertexField> fields;      // optional per-vertex fields
};

// Extracts the boundary of `complex`. Positions are taken from `positions`
// (#V by 3, e.g. deformed nodes) when given, else from the rest positions.
BoundarySurface ExtractBoundary(const CellComplex& complex,
                                const Points* positions = nullptr);

}  // namespace dynsolid::mesh
