// Readers of volume-mesh files into the control mesh's input form.
//
// Each returns a mesh::MeshInput: vertices (#V by 3, in the file's units,
// taken to be metres) and cells as lists of face loops, each loop oriented
// outward from its cell (right-hand normal pointing out). Faces shared by
// two cells appear in both, with opposite loops; identifying them and
// validating the complex is mesh::CellComplex::FromInput's job. `origin` is
// set to the path.
//
// Only linear volume cells become cells: tetrahedra, hexahedra, prisms
// (wedges), pyramids, and (VTK) polyhedra. Points, lines and surface cells
// (boundary or physical-group elements) are skipped. Anything else (second
// order, higher order, unknown types) is rejected, naming the type.
//
// Errors: NotFound when the file does not exist; otherwise
// InvalidArgument with a message "path:line: what was wrong and what was
// expected" (empty file, truncated section, bad number, undefined node,
// non-finite coordinate, binary file, unsupported element type...). Bad
// input never crashes: every count is checked against the file's size
// before memory is reserved for it.
//
// Files are read in one go and parsed in place; a million nodes take well
// under a second.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::io {

// Gmsh .msh, ASCII, format 2.x (2.2) or 4.1. Reads $MeshFormat, $Nodes and
// $Elements; skips $PhysicalNames, $Entities and any other section up to its
// $End tag. Node tags (any positive integers, possibly sparse) become vertex
// indices 0..n-1 in the order the nodes appear. Element types 4
// (tetrahedron), 5 (hexahedron), 6 (prism), 7 (pyramid) become cells using
// Gmsh's node ordering; 15 (point), 1 (line), 2 (triangle), 3 (quadrangle)
// are skipped; others are rejected. Binary files are rejected (convert with
// `gmsh in.msh -save -format msh41 -o out.msh`). Vertices that no volume
// element uses are dropped (mesh::DropUnusedVertices): vertex indices number
// the used nodes in the order they appear.
absl::StatusOr<mesh::MeshInput> ReadGmsh(const std::string& path);

// VTK legacy ASCII (`# vtk DataFile Version 2.0` .. `5.1`), DATASET
// UNSTRUCTURED_GRID: POINTS (float or double), CELLS in the classic layout
// (`CELLS n size`, each cell `count id...`) or the 5.1 layout (`CELLS
// nOffsets nConnectivity` with OFFSETS and CONNECTIVITY arrays), and
// CELL_TYPES. Cell types 10 (tetra), 11 (voxel, reordered to a
// hexahedron), 12 (hexahedron), 13 (wedge, mirrored to Gmsh's prism order),
// 14 (pyramid) and 42 (polyhedron) become cells; 0-9 (vertices, lines,
// polygons, quads...) are skipped; others are rejected.
//
// A polyhedron's list is a face stream: nFaces, then per face nPts followed
// by its point ids. VTK does not fix the orientation of polyhedron faces:
// when the faces of a polyhedron enclose negative volume, all its loops are
// reversed (faces oriented inconsistently with each other are left for
// CellComplex::FromInput to report). FIELD and METADATA blocks are skipped;
// reading stops at CELL_DATA / POINT_DATA. Points no volume cell uses are
// dropped, as for Gmsh.
absl::StatusOr<mesh::MeshInput> ReadVtkLegacy(const std::string& path);

// Dispatches on the extension (case-insensitive): .msh -> ReadGmsh, .vtk ->
// ReadVtkLegacy. InvalidArgument for any other extension.
absl::StatusOr<mesh::MeshInput> ReadMeshFile(const std::string& path);

}  // namespace dynsolid::io
