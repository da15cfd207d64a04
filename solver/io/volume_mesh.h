// A generic unstructured volume mesh (VTK's cell model) and its writer as
// VTK XML .vtu, for looking at the solid's elements in ParaView or loading
// them with meshio.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/fem/element_set.h"
#include "solver/mesh/points.h"

namespace dynsolid::io {

// A named array with one tuple per cell (cell data) or per point (point
// data): values[t * components + k] is component k of tuple t.
struct DataArray {
  std::string name;
  int components = 1;
  std::vector<double> values;  // #tuples * components
  // Written as Int32 (values must be whole numbers in range); else Float64.
  bool integer = false;
};

// Cells in VTU layout: cell c has VTK type types[c] and the point ids
// connectivity[offsets[c-1] .. offsets[c]) (offsets[-1] taken as 0), i.e.
// `offsets` holds END offsets, one per cell, as in the .vtu "offsets" array.
struct VolumeMesh {
  Points points;                      // #P by 3, metres
  std::vector<uint8_t> types;         // #C VTK cell types (10 tetra, 12 hexahedron, 14 pyramid...)
  std::vector<int64_t> offsets;       // #C end offsets into connectivity
  std::vector<int64_t> connectivity;  // point ids, in VTK node order per type
  std::vector<DataArray> cell_data;   // #C tuples each
  std::vector<DataArray> point_data;  // #P tuples each
};

// Writes `mesh` as VTK XML (VTKFile type="UnstructuredGrid" version="1.0"),
// ASCII: Float64 points and float arrays, Int64 connectivity and offsets,
// UInt8 types, Int32 integer arrays.
//
// InvalidArgument (nothing written) when the mesh is inconsistent: sizes
// that disagree, decreasing offsets, point ids out of range, a polyhedron
// (42, which needs face arrays this struct does not carry), non-finite
// values (VTK's ASCII reader cannot read "nan"), a non-integral value in an
// integer array, an empty array name or a repeated one. NotFound /
// PermissionDenied / Internal when the file cannot be written.
absl::Status WriteVtu(const std::string& path, const VolumeMesh& mesh);
// The same file's bytes appended to *bytes (nothing appended on error;
// messages name "vtu" where WriteVtu names the path).
absl::Status VtuBytes(const VolumeMesh& mesh, std::string* bytes);

// One VTK cell per finite element of `elements`, over the FEM nodes `nodes`
// (#elements.num_nodes() by 3: mesh vertices then virtual nodes, e.g. the
// deformed d = A p). Cells come in the order cubic, linear, pyramid:
//  - a cubic element becomes a VTK hexahedron (12) over its cell's 8
//    corners, the tensor nodes (i, j, k) in {1, 2}^3 taken in VTK order
//    (1,1,1) (2,1,1) (2,2,1) (1,2,1) (1,1,2) (2,1,2) (2,2,2) (1,2,2);
//  - a linear element a VTK hexahedron (12) over its 8 nodes;
//  - a pyramid element a VTK pyramid (14) over its 5 nodes.
// Integer cell data: `element_kind` (0 cubic, 1 linear, 2 pyramid), `cell`
// (the element's cell of the subdivided mesh), `control_cell`
// (cell_control_cell[cell], the level-0 cell it came from; when
// cell_control_cell is empty, the cell itself) and `level` (the constant
// `level`, the number of subdivision levels).
VolumeMesh ElementsToVolumeMesh(const Points& nodes, const fem::ElementSet& elements,
                                std::span<const int32_t> cell_control_cell, int level);

}  // namespace dynsolid::io
