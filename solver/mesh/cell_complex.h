// The control mesh: a cell complex of polyhedral cells (docs/model.md section 1).
//
// Vertices carry rest positions (#V by 3, metres). Faces are vertex loops
// (any n >= 3). Every face is stored once; a face has one or two cells:
// `face_cells(f)[0]` sees the stored loop as outward, `face_cells(f)[1]` (or
// -1 on the boundary) sees it reversed. So boundary face loops are outward.
//
// Adjacency (the role of the paper's radial-edge structure) is built once
// per topology change by the factory functions, all in flat CSR arrays:
// face -> edges/cells, edge -> faces/cells in radial order, vertex -> edges,
// faces, cells, cell -> faces/edges/vertices.
//
// A CellComplex is immutable after construction and cheap to move; share it
// as `std::shared_ptr<const CellComplex>` across threads.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/mesh/points.h"

namespace dynsolid::mesh {

// A mesh as files and generators describe it: each cell a list of faces,
// each face a loop of vertex indices oriented outward from that cell.
// A face shared by two cells appears in both, with opposite loops.
struct MeshInput {
  Points vertices;                                     // #V by 3
  std::vector<std::vector<std::vector<int32_t>>> cells;  // cell -> faces -> loop
  // Where the mesh came from ("scenes/chair.textproto", "block 3x3x3"), used
  // as the prefix of validation messages.
  std::string origin;
};

// Removes vertices that no cell uses and renumbers the rest in their old
// order (file readers call this: mesh files often carry geometry points).
// Returns how many were removed.
int32_t DropUnusedVertices(MeshInput& input);

// Compressed rows: row r is items[offsets[r] .. offsets[r+1]).
struct Csr {
  std::vector<int32_t> offsets{0};
  std::vector<int32_t> items;

  int32_t rows() const { return static_cast<int32_t>(offsets.size()) - 1; }
  std::span<const int32_t> row(int32_t r) const {
    return {items.data() + offsets[r],
            static_cast<size_t>(offsets[r + 1] - offsets[r])};
  }
  int32_t row_size(int32_t r) const { return offsets[r + 1] - offsets[r]; }
};

// One face of a cell, as that cell sees it.
struct CellFace {
  int32_t face;
  bool flipped;  // true: the cell sees the stored loop reversed
};

class CellComplex {
 public:
  CellComplex() = default;
  CellComplex(const CellComplex&) = default;
  CellComplex& operator=(const CellComplex&) = default;
  CellComplex(CellComplex&&) noexcept = default;
  CellComplex& operator=(CellComplex&&) noexcept = default;

  // Validates `input` (docs/model.md section 1) and builds the complex. Errors are
  // InvalidArgument and name the cell, face or vertex and the rule broken.
  // Every vertex must belong to a cell (see DropUnusedVertices).
  static absl::StatusOr<CellComplex> FromInput(const MeshInput& input);

  // Builds a complex whose faces are already identified: `face_loops` holds
  // every face once; `cell_faces` lists per cell its face ids, and
  // `cell_face_flipped` (same layout as cell_faces.items) whether the cell
  // sees that loop reversed. Used by subdivision, where faces are known by
  // construction. Runs the cheap structural checks; `validate_geometry`
  // also checks cell volumes (off on hot paths). `check_closed` false
  // skips CheckCellsClosed, for a caller whose cells are closed by
  // construction (a subdivision's fine cells from closed parents: a
  // third of the finest level's adjacency time on the chair).
  static absl::StatusOr<CellComplex> FromFaces(Points vertices, Csr face_loops,
                                               Csr cell_faces,
                                               std::vector<uint8_t> cell_face_flipped,
                                               bool validate_geometry, bool check_closed = true);

  int32_t num_vertices() const { return static_cast<int32_t>(positions_.rows()); }
  int32_t num_faces() const { return face_vertices_.rows(); }
  int32_t num_edges() const { return static_cast<int32_t>(edge_vertices_.size()); }
  int32_t num_cells() const { return cell_faces_.rows(); }

  const Points& positions() const { return positions_; }

  // Face f's vertex loop as stored; edge i of the face joins loop[i] and
  // loop[i+1 mod n] and is face_edges(f)[i].
  std::span<const int32_t> face_vertices(int32_t f) const { return face_vertices_.row(f); }
  std::span<const int32_t> face_edges(int32_t f) const { return face_edges_.row(f); }
  // [0]: cell that sees the stored loop as outward; [1]: the other cell or -1.
  const std::array<int32_t, 2>& face_cells(int32_t f) const { return face_cells_[f]; }
  bool face_is_boundary(int32_t f) const { return face_cells_[f][1] < 0; }

  // Edge endpoints, smaller index first.
  const std::array<int32_t, 2>& edge_vertices(int32_t e) const { return edge_vertices_[e]; }
  // Faces around the edge in radial order: consecutive faces share a cell;
  // for a boundary edge the walk starts and ends at boundary faces.
  std::span<const int32_t> edge_faces(int32_t e) const { return edge_faces_.row(e); }
  // Cells around the edge, in the same radial order.
  std::span<const int32_t> edge_cells(int32_t e) const { return edge_cells_.row(e); }
  bool edge_is_boundary(int32_t e) const { return edge_boundary_[e] != 0; }

  std::span<const int32_t> vertex_edges(int32_t v) const { return vertex_edges_.row(v); }
  std::span<const int32_t> vertex_faces(int32_t v) const { return vertex_faces_.row(v); }
  std::span<const int32_t> vertex_cells(int32_t v) const { return vertex_cells_.row(v); }
  bool vertex_is_boundary(int32_t v) const { return vertex_boundary_[v] != 0; }

  // Faces of cell c (ids) and, in the same order, whether c sees each reversed.
  std::span<const int32_t> cell_faces(int32_t c) const { return cell_faces_.row(c); }
  std::span<const uint8_t> cell_face_flipped(int32_t c) const {
    return {cell_face_flipped_.data() + cell_faces_.offsets[c],
            static_cast<size_t>(cell_faces_.row_size(c))};
  }
  std::span<const int32_t> cell_edges(int32_t c) const { return cell_edges_.row(c); }
  std::span<const int32_t> cell_vertices(int32_t c) const { return cell_vertices_.row(c); }

  // Face f's loop as cell c sees it (outward from c). `out` is overwritten.
  void CellFaceLoop(int32_t c, int32_t local_face, std::vector<int32_t>& out) const;

  // Edge id joining a and b, or -1.
  int32_t FindEdge(int32_t a, int32_t b) const;

  // Geometry at rest positions.
  Eigen::Vector3d FaceCentroid(int32_t f) const;     // average of the loop's vertices
  Eigen::Vector3d CellCentroid(int32_t c) const;     // average of the cell's vertices
  double CellVolume(int32_t c) const;                // signed; positive when outward
  bool CellIsHexahedron(int32_t c) const;            // 6 quads, 8 vertices, 12 edges

  // Number of boundary vertices, edges and faces and their Euler
  // characteristic V - E + F (2 per sphere-like boundary component, 0 per torus).
  struct BoundaryCounts {
    int64_t vertices = 0, edges = 0, faces = 0;
    int64_t euler() const { return vertices - edges + faces; }
  };
  BoundaryCounts CountBoundary() const;

  // Replaces rest positions (same topology). Sizes must match.
  void set_positions(Points p) { positions_ = std::move(p); }

  // Whether every cell is a closed, consistently oriented polyhedron:
  // each of its edges lies in exactly two of its faces, traversed in
  // opposite directions. The first error found, naming the cell, edge
  // and faces. FromInput and FromFaces run it unless told the cells are
  // closed by construction.
  absl::Status CheckCellsClosed() const;

 private:
  // The relations from cells' faces and face loops, then (check_closed)
  // the cells' closedness (CheckCellsClosed): the first error found.
  absl::Status BuildAdjacency(bool check_closed);
  // Complexes of this many cells build part of their adjacency on a
  // second thread (a thread costs tens of microseconds; 512 cells' side
  // share, a few hundred).
  static constexpr int32_t kCellsForAThread = 512;
  absl::Status CheckVolumes(const std::string& origin) const;

  Points positions_;
  Csr face_vertices_;
  Csr face_edges_;
  std::vector<std::array<int32_t, 2>> face_cells_;
  std::vector<std::array<int32_t, 2>> edge_vertices_;
  Csr edge_faces_;
  Csr edge_cells_;
  std::vector<uint8_t> edge_boundary_;
  Csr vertex_edges_;
  Csr vertex_faces_;
  Csr vertex_cells_;
  std::vector<uint8_t> vertex_boundary_;
  Csr cell_faces_;
  std::vector<uint8_t> cell_face_flipped_;
  Csr cell_edges_;
  Csr cell_vertices_;
};

}  // namespace dynsolid::mesh
