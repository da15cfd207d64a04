// The local-frame deformation measure R (docs/model.md 4a): a per-node vector
// delta built only from changes of edge lengths and face corner angles, so
// it is blind to rigid motion.
//  - stretch, per edge (i, j): delta_i -= (l - l0)/2 e_ij,
//    delta_j += (l - l0)/2 e_ij;
//  - shear, per face corner (n; a, b): rotate a by +(theta - theta0)/2 and
//    b by -(theta - theta0)/2 about n along (a - n) x (b - n), which brings
//    the angle back to theta0; delta_a += a - a', delta_b += b - b'.
// Edges and faces are those of the level-L mesh plus, for pyramid
// elements, the edges from the virtual centre node to its cell's vertices
// and the triangles it spans with the cell's face edges.
//
// Parallel layout ("owner computes"): the level-L cells are split into
// `parts` contiguous ranges; a node belongs to the part of its
// lowest-numbered cell (a virtual node to its cell's part). Part k visits,
// in ascending order, every edge and corner that touches one of its nodes
// and adds their terms to its own nodes only. Each node's sum is therefore
// taken in one global order (its edges ascending, then its corners
// ascending) whatever the number of parts or threads, no part writes
// another's rows, and there are no per-thread buffers to clear and add.
// Terms of edges and corners on a boundary between parts are computed by
// each part they touch (a few percent of the work on large meshes).
//
// Quadrilateral faces (every face of a subdivided hexahedral mesh) are
// processed whole, their four corners in four SIMD lanes, two faces at a time
// in two AVX2 registers, or four in two AVX-512 registers where the CPU has
// them (QuadPath): the face's four node rows are loaded once and transposed,
// each corner's sides are lane rotations of them, and each node's share of
// the face (the terms of the two or three corners that touch it) is summed in
// registers and added to its row once. An edge that is a side of a
// quadrilateral runs with the first such quadrilateral (its stretch term from
// the side's length and inverse, which the corners compute anyway) instead of
// in the edge list. Per node the sums run over its remaining edges, then its
// quadrilaterals (corners and fused sides), then its other corners, each list
// ascending: still one global order. Without AVX2, or with
// QuadPath::kPerCorner (the reference the tests hold the quadrilateral path
// to), every corner goes through the per-corner path.
#pragma once

#include <array>
#include <cstdint>
#include <initializer_list>
#include <vector>

#include "solver/fem/element_set.h"
#include "solver/mesh/cell_complex.h"
#include "solver/models/measure_quads.h"

namespace dynsolid::models {

// How the corners of quadrilateral faces run. kAvx2 and kAvx512 issue the
// same operations in the same order and give the same bits; kPerCorner
// sums the same terms in another order (agreement to rounding).
enum class QuadPath : uint8_t {
  kPerCorner,  // each corner alone, in the per-corner loops
  kAvx2,       // four corners to an AVX2 register, two faces at a time
  kAvx512,     // two faces to an AVX-512 register, four at a time
};
// Whether this build and this CPU run `path`.
bool QuadPathRuns(QuadPath path);
// The widest path that runs here (kPerCorner without AVX2).
QuadPath FastestQuadPath();
// "per-corner", "avx2", "avx512".
const char* QuadPathName(QuadPath path);

class DeformationMeasure {
 public:
  DeformationMeasure() = default;
  // `quads`: a path that does not run here falls back to FastestQuadPath()
  // (quad_path() says which runs).
  DeformationMeasure(const mesh::CellComplex& mesh, const fem::ElementSet& elements,
                     const Points& rest, int parts, QuadPath quads = FastestQuadPath());

  QuadPath quad_path() const { return quad_path_; }

  int parts() const { return static_cast<int>(parts_.size()); }

  // delta (#nodes by 3) for node positions d: part k writes the rows of its
  // nodes (all of them, zeros included). `delta` must already have d.rows()
  // rows.
  void ForwardPart(const Points& d, int k, Points& delta) const;

  // out = (d delta / d d)^T y at positions d (the transpose of the
  // measure's Jacobian): for an energy E(delta), the force is
  // dE/dd = (d delta / d d)^T dE/d delta. Part k writes the rows of its
  // nodes; `out` must have y.rows() rows. The geometry is recomputed from
  // d, not kept from the forward pass: the measure holds no per-term state.
  void TransposePart(const Points& d, const Points& y, int k, Points& out) const;

  // Whole-measure conveniences (tests): all parts in turn, resizing outputs.
  void Apply(const Points& d, Points& delta) const;
  void ApplyTranspose(const Points& d, const Points& y, Points& out) const;

  int64_t num_edges() const { return num_edges_; }
  int64_t num_corners() const { return num_corners_; }
  // Quadrilaterals whose four corners run together (their corners count in
  // num_corners()).
  int64_t num_quads() const { return num_quads_; }
  // Edge and corner terms computed per pass, counting those computed by
  // two or more parts once for each (>= num_edges() + num_corners()).
  int64_t terms_per_pass() const;
  // Bytes the measure keeps: its parts' node, edge and corner lists (node
  // ids, rest lengths or their indices, rest angles or their indices,
  // ownership bits) and the tables of distinct rest values. No per-term
  // state.
  int64_t bytes() const;

 private:
  // A part's edges and corners in structure-of-arrays form, so the
  // geometry loops run in SIMD lanes (gathers in, per-term results out),
  // and the adds into the part's own nodes follow as a scalar loop in
  // ascending term order. `owns` bits: 1 the first node (edge i, corner a),
  // 2 the second (edge j, corner b), 4 the corner's centre n.
  struct Part {
    std::vector<int32_t> nodes;  // owned, ascending
    // Edges touching an owned node, ascending.
    std::vector<int32_t> ei, ej;
    std::vector<uint32_t> e_rest;  // rows of edge_rest_
    std::vector<uint8_t> e_owns;
    // Quadrilaterals touching an owned node, ascending: their nodes in loop
    // order (4 each; corner k is at node k, between nodes k - 1 and k + 1),
    // their rest corners (rows of quad_rest_), and bit k set when node k
    // is owned.
    std::vector<int32_t> qv;
    std::vector<uint32_t> q_rest;
    std::vector<uint8_t> q_owns;
    // Other corners touching an owned node, ascending.
    std::vector<int32_t> cn, ca, cb;
    std::vector<double> cos0, sin0;
    std::vector<uint8_t> c_owns;
  };
  // Clears the part's nodes in `out` (#nodes by 3, row-major), then adds
  // the part's edge terms (f: -1 on i, +1 on j), its quadrilaterals' terms
  // (quad_terms adds them itself) and its other corner terms (ta on a, tb
  // on b, and with `centres` -(ta + tb) on n) to the nodes it owns, in
  // ascending term order, computing edges and corners chunk by chunk with
  // edge_terms and corner_terms.
  template <typename EdgeTerms, typename QuadTerms, typename CornerTerms>
  static void RunPart(const Part& p, bool centres, double* out,
                      std::initializer_list<const double*> inputs, EdgeTerms edge_terms,
                      QuadTerms quad_terms, CornerTerms corner_terms);

  QuadPath quad_path_ = QuadPath::kPerCorner;
  // The quadrilateral kernels of quad_path_ (null for kPerCorner, which
  // then has no quadrilaterals).
  measure_detail::QuadKernels quads_;
  int64_t num_edges_ = 0, num_corners_ = 0, num_quads_ = 0;
  std::vector<uint8_t> owner_;  // node -> part
  // The distinct rest lengths of edges, and the distinct rest corners of
  // quadrilaterals (the cosines then the sines of their four rest angles,
  // 8 per row), which the parts' terms index.
  std::vector<double> edge_rest_, quad_rest_;
  std::vector<Part> parts_;
};

}  // namespace dynsolid::models
