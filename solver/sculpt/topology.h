// Topology edits on the control mesh (docs/model.md section 8).
//
// Every edit is a pure function of
//   rest     the control complex at rest (positions in metres),
//   current  the same vertices' current (deformed) positions, #V by 3, metres,
//   sharp    the current sharp tags, one per edge of `rest` (empty: none sharp),
//   the edit's own arguments,
// to an EditResult or an InvalidArgument error that names the argument and
// item ("faces[1]: face 12 is interior ...") and the rule broken. Bad input
// never yields a partial result: every result has been rebuilt with
// mesh::CellComplex::FromInput (closed cells, consistent orientation,
// positive rest volumes) and checked to be manifold (no two parts touching
// only along an edge or at a vertex) before it is returned.
//
// Determinism: the same input gives the same output bits (no hashing, no
// threads; every loop runs in index order).
//
// Sharp edges go in as tags per rest edge and come back as the new mesh's
// sharp edges as vertex pairs: edge ids are not stable across an edit (FromInput numbers edges afresh), vertex
// pairs are, and subdivision::SharpEdgesFromPairs turns pairs back into
// tags for the rebuilt complex.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/mesh/cell_complex.h"
#include "solver/mesh/points.h"

namespace dynsolid::sculpt {

struct EditResult {
  // The new control mesh at REST: cells as outward face loops. New vertex
  // ids: survivors first in their old order, then new vertices.
  mesh::MeshInput mesh;
  // The same as mesh::CellComplex::FromInput(mesh) made it for the checks
  // below (a rebuild discretizes it without building it again).
  std::shared_ptr<mesh::CellComplex> complex;
  // #new vertices by 3: the same vertices in the CURRENT configuration.
  Points current;
  // Per new vertex: the old vertices it comes from with weights summing to 1
  // ({old, 1} for a survivor; {face vertex, 1} for an extruded vertex; the
  // row of the subdivision matrix for a refined vertex; {a_i, 1} for merge,
  // which adds no vertex). Used to carry velocities over.
  std::vector<std::vector<std::pair<int32_t, double>>> vertex_sources;
  // Per new cell: the old cell it is (or was refined from), -1 for a new cell.
  std::vector<int32_t> cell_source;
  // Sharp control edges of the new mesh as vertex pairs (new ids, smaller
  // first), in the new complex's edge order.
  std::vector<std::array<int32_t, 2>> sharp_edges;
  // One line for logs and clients, e.g.
  // "extruded 1 face by 0.2 m in 1 layer: +1 cell, +4 vertices".
  std::string summary;
};

// Deletes `cells` (ids of `rest`, distinct, in range). Faces they shared with
// survivors become boundary; vertices no survivor uses go; survivors keep
// their old relative order. Refuses an empty list, deleting every cell, and a
// non-manifold result. Splitting the solid into several components is allowed.
absl::StatusOr<EditResult> DeleteCells(const mesh::CellComplex& rest, const Points& current,
                                       const std::vector<uint8_t>& sharp,
                                       std::span<const int32_t> cells);

inline constexpr int kMaxExtrudeLayers = 16;

// Extrudes the boundary faces `faces` (distinct) by `distance` metres (> 0,
// finite) in `layers` equal layers (1..kMaxExtrudeLayers). Vertex v moves
// along n_v, the normalized sum of the unit normals of the selected faces at
// v (a patch extrudes as one, sharing side faces; a lone face uses its own
// normal). One new cell per face per layer: the face, its copy, and one side
// quad per face edge (a hexahedron for a quad, a prism for a triangle). The
// same decisions are applied twice: rest positions from rest normals, current
// positions from current normals, so new material grows where the deformed
// solid is. New vertices' sources are the face vertices they came from.
absl::StatusOr<EditResult> ExtrudeFaces(const mesh::CellComplex& rest, const Points& current,
                                        const std::vector<uint8_t>& sharp,
                                        std::span<const int32_t> faces, double distance,
                                        int layers);

// Joins two distinct boundary faces with the same vertex count k and no
// common vertex by one new cell: face_a and face_b (both reversed, so they
// become interior) and k side quads. Vertex a_i pairs with b_{(s - i) mod k},
// the shift s minimising the summed rest distance (ties: smallest s). Only
// this orientation gives the new cell consistent face loops (face_b is seen
// reversed from face_a's side); the other one would need a twisted cell.
// The summary says whether it joined two components or made a handle, with
// the boundary Euler characteristic before and after.
absl::StatusOr<EditResult> MergeFaces(const mesh::CellComplex& rest, const Points& current,
                                      const std::vector<uint8_t>& sharp, int32_t face_a,
                                      int32_t face_b);

// Local MacCracken-Joy subdivision of `cells` (distinct, in range):
// subdivision::SubdivideOnce with options.cells. Current positions are
// level.a * current; vertex sources are the rows of level.a; cell sources
// are level.parent_cell; sharp tags are the ones SubdivideOnce returns.
absl::StatusOr<EditResult> SubdivideCells(const mesh::CellComplex& rest, const Points& current,
                                          const std::vector<uint8_t>& sharp,
                                          std::span<const int32_t> cells);

// Tags (sharp = true) or untags the edges given as vertex pairs; every pair
// must be an edge of `rest`. Topology and positions are unchanged.
absl::StatusOr<EditResult> SetSharp(const mesh::CellComplex& rest, const Points& current,
                                    const std::vector<uint8_t>& sharp,
                                    std::span<const std::array<int32_t, 2>> edges, bool on);

}  // namespace dynsolid::sculpt
