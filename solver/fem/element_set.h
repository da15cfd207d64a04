// Element classification on the subdivided mesh (docs/model.md section 3).
//
// Each level-L cell gets elements by kind:
//  - cubic (BE): a hexahedron whose faces and vertices are interior, whose
//    8 vertices have 6 edges each and whose 26 neighbours are hexahedra.
//    Its 64 nodes are the 4x4x4 block of vertices around it, stored in
//    tensor order m = 16 i + 4 j + k (i along u, j along v, k along w, each
//    0..3; the cell itself spans indices 1..2), so shape function m is
//    B_i(u) B_j(v) B_k(w). The paper's Fig. 6 lists the same 64 nodes by
//    kind (the cell's 8, 24 face, 24 edge, 8 vertex neighbours); tensor
//    order is that set in an order the kernels can index directly.
//  - linear (LE): every other hexahedron: 8 nodes in VTK hexahedron order
//    (0-3 bottom loop, 4-7 above them, right-handed: positive volume).
//  - pyramid (PE): every other cell gets a virtual node at the average of
//    its vertices (an extra row of A, so it moves with them) and one
//    pyramid per face: nodes in VTK pyramid order (base loop whose normal
//    points at the apex, then the apex = the virtual node). A triangular
//    face (possible only at level 0) repeats its last vertex; a face with
//    more than 4 vertices is fanned into triangles from its first vertex.
//
// FEM nodes are the mesh vertices followed by the virtual nodes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "solver/mesh/cell_complex.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::fem {

enum class ElementKind : uint8_t { kCubic = 0, kLinear = 1, kPyramid = 2 };

inline constexpr int kCubicNodes = 64;
inline constexpr int kLinearNodes = 8;
inline constexpr int kPyramidNodes = 5;

struct ElementSet {
  int32_t num_mesh_vertices = 0;
  int32_t num_virtual_nodes = 0;
  int32_t num_nodes() const { return num_mesh_vertices + num_virtual_nodes; }

  std::vector<int32_t> cubic_nodes;    // 64 per element, tensor order
  std::vector<int32_t> cubic_cell;     // element -> mesh cell
  std::vector<int32_t> linear_nodes;   // 8 per element, VTK hexahedron order
  std::vector<int32_t> linear_cell;
  std::vector<int32_t> pyramid_nodes;  // 5 per element, VTK pyramid order
  std::vector<int32_t> pyramid_cell;
  std::vector<int32_t> virtual_node_cell;  // virtual node -> its mesh cell

  int32_t num_cubic() const { return static_cast<int32_t>(cubic_cell.size()); }
  int32_t num_linear() const { return static_cast<int32_t>(linear_cell.size()); }
  int32_t num_pyramid() const { return static_cast<int32_t>(pyramid_cell.size()); }
  int32_t num_pyramid_cells() const { return num_virtual_nodes; }
};

// Classifies every cell of `mesh`. Never fails on a valid complex.
ElementSet ClassifyElements(const mesh::CellComplex& mesh);

// The FEM node matrix: `a` (mesh vertices x control) extended by one row
// per virtual node that averages its cell's rows. #nodes x control.
subdivision::SparseMatrix NodeMatrix(const mesh::CellComplex& mesh,
                                     const subdivision::SparseMatrix& a,
                                     const ElementSet& elements);

}  // namespace dynsolid::fem
