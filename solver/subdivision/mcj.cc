#include "solver/subdivision/mcj.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <thread>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"

namespace dynsolid::subdivision {
namespace {

using mesh::CellComplex;
using mesh::Csr;

// One sparse row summed in a dense slot per column (a subdivision
// stencil's hundreds of terms, or a product row's, over a few dozen
// columns): a column's terms summed in the order they were added, the
// first one taken as it is; emitted in ascending column order, from a
// bitset of the columns where scanning its words costs less than sorting
// the row's columns (a control mesh of a few hundred points: a handful of
// words), else by sorting them (the same columns and values either way).
class RowBuilder {
 public:
  explicit RowBuilder(int32_t cols)
      : sum_(cols, 0.0), seen_(cols, 0), bits_((cols + 63) / 64, 0) {}
  void Add(int32_t col, double w) {
    if (!seen_[col]) {
      seen_[col] = 1;
      sum_[col] = w;
      cols_.push_back(col);
    } else {
      sum_[col] += w;
    }
  }
  // Adds w times the average of the vertices in `cols`.
  void AddAverage(std::span<const int32_t> cols, double w) {
    const double s = w / static_cast<double>(cols.size());
    for (int32_t c : cols) Add(c, s);
  }
  // Appends the row to inner and values and starts the next; returns its
  // number of entries.
  int32_t Emit(std::vector<int32_t>& inner, std::vector<double>& values) {
    const int64_t words = static_cast<int64_t>(bits_.size());
    if (words <= 4 * static_cast<int64_t>(cols_.size())) {
      for (int32_t c : cols_) bits_[c >> 6] |= uint64_t{1} << (c & 63);
      cols_.clear();
      for (int64_t w = 0; w < words; ++w) {
        for (uint64_t m = bits_[w]; m != 0; m &= m - 1) {
          cols_.push_back(static_cast<int32_t>(64 * w + __builtin_ctzll(m)));
        }
        bits_[w] = 0;
      }
    } else {
      std::sort(cols_.begin(), cols_.end());
    }
    for (int32_t col : cols_) {
      inner.push_back(col);
      values.push_back(sum_[col]);
      seen_[col] = 0;
    }
    const int32_t n = static_cast<int32_t>(cols_.size());
    cols_.clear();
    return n;
  }
  // Emit, then the row's end in outer.
  void Flush(std::vector<int32_t>& outer, std::vector<int32_t>& inner,
             std::vector<double>& values) {
    Emit(inner, values);
    outer.push_back(static_cast<int32_t>(inner.size()));
  }

 private:
  std::vector<double> sum_;
  std::vector<uint8_t> seen_;
  std::vector<uint64_t> bits_;
  std::vector<int32_t> cols_;
};

// Newell normal of a face loop (not normalised).
Eigen::Vector3d FaceNormal(const CellComplex& m, int32_t f) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  const auto loop = m.face_vertices(f);
  const size_t k = loop.size();
  for (size_t i = 0; i < k; ++i) {
    const Eigen::Vector3d a = m.positions().row(loop[i]).transpose();
    const Eigen::Vector3d b = m.positions().row(loop[(i + 1) % k]).transpose();
    n += a.cross(b);
  }
  return n;
}

}  // namespace

SparseMatrix FromCsr(int32_t rows, int32_t cols, const std::vector<int32_t>& outer,
                     const std::vector<int32_t>& inner, const std::vector<double>& values) {
  SparseMatrix m(rows, cols);
  m.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), m.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), m.innerIndexPtr());
  std::copy(values.begin(), values.end(), m.valuePtr());
  return m;
}

SparseMatrix MultiplyRowMajor(const SparseMatrix& a, const SparseMatrix& b) {
  const int32_t rows = static_cast<int32_t>(a.rows()), cols = static_cast<int32_t>(b.cols());
  struct Part {
    std::vector<int32_t> row_nnz, inner;
    std::vector<double> values;
  };
  // Rows in contiguous parts of 1024 or more, each thread taking the next
  // part with its own dense accumulator (RowBuilder; the finest level's
  // product runs beside the element classification); joined in order, so
  // the result does not depend on the thread count or the timing.
  std::vector<Part> parts(16);
  const int threads = BuildThreads();
  std::vector<std::optional<RowBuilder>> builders(threads);
  const double per_row = b.rows() > 0 ? static_cast<double>(b.nonZeros()) / b.rows() : 0.0;
  const int chunks = ParallelParts(rows, threads, static_cast<int>(parts.size()), 1024,
                                   [&](int t, int k, int64_t begin, int64_t end) {
    Part& p = parts[k];
    if (!builders[t].has_value()) builders[t].emplace(cols);
    RowBuilder& row = *builders[t];
    const double a_nnz = static_cast<double>(a.outerIndexPtr()[end] - a.outerIndexPtr()[begin]);
    p.inner.reserve(static_cast<size_t>(a_nnz * per_row / 4.0));
    p.values.reserve(p.inner.capacity());
    p.row_nnz.reserve(end - begin);
    for (int32_t i = static_cast<int32_t>(begin); i < end; ++i) {
      for (SparseMatrix::InnerIterator ia(a, i); ia; ++ia) {
        const double w = ia.value();
        for (SparseMatrix::InnerIterator ib(b, ia.col()); ib; ++ib) {
          row.Add(static_cast<int32_t>(ib.col()), w * ib.value());
        }
      }
      p.row_nnz.push_back(row.Emit(p.inner, p.values));
    }
  });
  size_t nnz = 0;
  for (int k = 0; k < chunks; ++k) nnz += parts[k].inner.size();
  SparseMatrix m(rows, cols);
  m.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int32_t* outer = m.outerIndexPtr();
  outer[0] = 0;
  int32_t r = 0;
  size_t at = 0;
  for (int k = 0; k < chunks; ++k) {
    Part& p = parts[k];
    for (int32_t n : p.row_nnz) {
      outer[r + 1] = outer[r] + n;
      ++r;
    }
    std::copy(p.inner.begin(), p.inner.end(), m.innerIndexPtr() + at);
    std::copy(p.values.begin(), p.values.end(), m.valuePtr() + at);
    at += p.inner.size();
    p = Part();
  }
  return m;
}

namespace {

// Which coarse elements a subdivision splits: the fine point of each split
// edge, face and cell (-1: not split), and the "frozen" ones, which also
// touch an unrefined cell and are split linearly so that cell keeps its
// shape.
struct Split {
  std::vector<int32_t> edge_point, face_point, cell_point;
  std::vector<uint8_t> edge_frozen, face_frozen, vertex_frozen;
  int32_t fine_vertices = 0;
};

// The rows of the subdivision matrix, appended in CSR form to outer, inner
// and values by the steps below (old vertices' points, then edge, face and
// cell points: the fine vertex order), each row summed by `row`.
struct MatrixRows {
  std::vector<int32_t> outer{0}, inner;
  std::vector<double> values;
};

// Old vertices -> vertex points. sharp_edges: per edge, nonzero where
// tagged (empty: none).
void AddVertexPointRows(const CellComplex& m, const Split& split,
                        const std::vector<uint8_t>& sharp_edges, RowBuilder& row,
                        MatrixRows& rows) {
  const int32_t nv = m.num_vertices();
  auto sharp = [&](int32_t e) { return !sharp_edges.empty() && sharp_edges[e] != 0; };
  const std::vector<uint8_t>& vertex_frozen = split.vertex_frozen;
  std::vector<int32_t> boundary_faces, boundary_edges, sharp_nbrs;
  for (int32_t v = 0; v < nv; ++v) {
    sharp_nbrs.clear();
    for (int32_t e : m.vertex_edges(v)) {
      if (!sharp(e)) continue;
      const auto& ev = m.edge_vertices(e);
      sharp_nbrs.push_back(ev[0] == v ? ev[1] : ev[0]);
    }
    boundary_faces.clear();
    boundary_edges.clear();
    if (m.vertex_is_boundary(v)) {
      for (int32_t f : m.vertex_faces(v)) {
        if (m.face_is_boundary(f)) boundary_faces.push_back(f);
      }
      for (int32_t e : m.vertex_edges(v)) {
        if (m.edge_is_boundary(e)) boundary_edges.push_back(e);
      }
    }
    if (vertex_frozen[v] || sharp_nbrs.size() >= 3 ||
        (m.vertex_is_boundary(v) && sharp_nbrs.size() < 2 &&
         boundary_faces.size() != boundary_edges.size())) {
      // Unrefined neighbour, sharp corner, or a non-manifold boundary vertex.
      row.Add(v, 1.0);
    } else if (sharp_nbrs.size() == 2) {
      // Crease: cubic B-spline curve rule (a + 6 V + b) / 8.
      row.Add(sharp_nbrs[0], 1.0 / 8.0);
      row.Add(v, 6.0 / 8.0);
      row.Add(sharp_nbrs[1], 1.0 / 8.0);
    } else if (m.vertex_is_boundary(v)) {
      // Catmull-Clark on the boundary surface: (Fbar + 2 Rbar + (n - 3) V) / n
      // with face points = face centroids and R = boundary edge midpoints.
      const double n = static_cast<double>(boundary_faces.size());
      for (int32_t f : boundary_faces) row.AddAverage(m.face_vertices(f), 1.0 / (n * n));
      for (int32_t e : boundary_edges) {
        const auto& ev = m.edge_vertices(e);
        row.Add(ev[0], 1.0 / (n * n));
        row.Add(ev[1], 1.0 / (n * n));
      }
      row.Add(v, (n - 3.0) / n);
    } else {
      // Interior: (Cbar + 3 Abar + 3 Ebar + (n - 7) V) / n, n cells around v.
      const auto cells = m.vertex_cells(v);
      const auto faces = m.vertex_faces(v);
      const auto edges = m.vertex_edges(v);
      const double n = static_cast<double>(cells.size());
      for (int32_t c : cells) {
        row.AddAverage(m.cell_vertices(c), 1.0 / (n * static_cast<double>(cells.size())));
      }
      for (int32_t f : faces) {
        row.AddAverage(m.face_vertices(f), 3.0 / (n * static_cast<double>(faces.size())));
      }
      for (int32_t e : edges) {
        const auto& ev = m.edge_vertices(e);
        const double w = 3.0 / (n * static_cast<double>(edges.size()) * 2.0);
        row.Add(ev[0], w);
        row.Add(ev[1], w);
      }
      row.Add(v, (n - 7.0) / n);
    }
    row.Flush(rows.outer, rows.inner, rows.values);
  }
}

// Edge points, one row per split edge (sharp_edges as above).
void AddEdgePointRows(const CellComplex& m, const Split& split,
                      const std::vector<uint8_t>& sharp_edges, RowBuilder& row,
                      MatrixRows& rows) {
  const int32_t ne = m.num_edges();
  auto sharp = [&](int32_t e) { return !sharp_edges.empty() && sharp_edges[e] != 0; };
  const std::vector<int32_t>& edge_point = split.edge_point;
  const std::vector<uint8_t>& edge_frozen = split.edge_frozen;
  std::vector<int32_t> boundary_faces;
  for (int32_t e = 0; e < ne; ++e) {
    if (edge_point[e] < 0) continue;
    const auto& ev = m.edge_vertices(e);
    boundary_faces.clear();
    if (m.edge_is_boundary(e)) {
      for (int32_t f : m.edge_faces(e)) {
        if (m.face_is_boundary(f)) boundary_faces.push_back(f);
      }
    }
    if (edge_frozen[e] || sharp(e) ||
        (m.edge_is_boundary(e) && boundary_faces.size() != 2)) {
      row.Add(ev[0], 0.5);
      row.Add(ev[1], 0.5);
    } else if (m.edge_is_boundary(e)) {
      // (v0 + v1 + F0 + F1) / 4 with the boundary face points (centroids).
      row.Add(ev[0], 0.25);
      row.Add(ev[1], 0.25);
      row.AddAverage(m.face_vertices(boundary_faces[0]), 0.25);
      row.AddAverage(m.face_vertices(boundary_faces[1]), 0.25);
    } else {
      // (Cbar + 2 Abar + (n - 3) Mid) / n, n cells around the edge.
      const auto cells = m.edge_cells(e);
      const auto faces = m.edge_faces(e);
      const double n = static_cast<double>(cells.size());
      for (int32_t c : cells) {
        row.AddAverage(m.cell_vertices(c), 1.0 / (n * static_cast<double>(cells.size())));
      }
      for (int32_t f : faces) {
        row.AddAverage(m.face_vertices(f), 2.0 / (n * static_cast<double>(faces.size())));
      }
      row.Add(ev[0], (n - 3.0) / (2.0 * n));
      row.Add(ev[1], (n - 3.0) / (2.0 * n));
    }
    row.Flush(rows.outer, rows.inner, rows.values);
  }
}

// Face points, one row per split face.
void AddFacePointRows(const CellComplex& m, const Split& split, RowBuilder& row,
                      MatrixRows& rows) {
  const int32_t nf = m.num_faces();
  const std::vector<int32_t>& face_point = split.face_point;
  const std::vector<uint8_t>& face_frozen = split.face_frozen;
  for (int32_t f = 0; f < nf; ++f) {
    if (face_point[f] < 0) continue;
    if (face_frozen[f] || m.face_is_boundary(f)) {
      row.AddAverage(m.face_vertices(f), 1.0);
    } else {
      // (C0 + 2 A + C1) / 4.
      const auto& fc = m.face_cells(f);
      row.AddAverage(m.cell_vertices(fc[0]), 0.25);
      row.AddAverage(m.face_vertices(f), 0.5);
      row.AddAverage(m.cell_vertices(fc[1]), 0.25);
    }
    row.Flush(rows.outer, rows.inner, rows.values);
  }
}

// Cell points: the centroid of the cell's vertices.
void AddCellPointRows(const CellComplex& m, const Split& split, RowBuilder& row,
                      MatrixRows& rows) {
  const int32_t nc = m.num_cells();
  for (int32_t c = 0; c < nc; ++c) {
    if (split.cell_point[c] < 0) continue;
    row.AddAverage(m.cell_vertices(c), 1.0);
    row.Flush(rows.outer, rows.inner, rows.values);
  }
}

// The subdivision matrix (fine vertices x coarse vertices), from the coarse
// complex alone. sharp_edges: per edge, nonzero where tagged (empty: none).
SparseMatrix SubdivisionMatrix(const CellComplex& m, const Split& split,
                               const std::vector<uint8_t>& sharp_edges) {
  const int32_t nv = m.num_vertices();
  const int32_t nv_fine = split.fine_vertices;
  // ---- The subdivision matrix, row by row. ----
  MatrixRows rows;
  rows.outer.reserve(nv_fine + 1);
  rows.inner.reserve(static_cast<size_t>(nv_fine) * 27);
  rows.values.reserve(static_cast<size_t>(nv_fine) * 27);
  RowBuilder row(nv);
  AddVertexPointRows(m, split, sharp_edges, row, rows);
  AddEdgePointRows(m, split, sharp_edges, row, rows);
  AddFacePointRows(m, split, row, rows);
  AddCellPointRows(m, split, row, rows);
  return FromCsr(nv_fine, nv, rows.outer, rows.inner, rows.values);
}

// Which cells a subdivision refines: all when `cells` is empty, else
// those listed (each must be a cell of the complex).
absl::StatusOr<std::vector<uint8_t>> RefinedCells(int32_t nc, const std::vector<int32_t>& cells) {
  std::vector<uint8_t> refined(nc, cells.empty() ? 1 : 0);
  for (int32_t c : cells) {
    if (c < 0 || c >= nc) {
      return absl::InvalidArgumentError(
          absl::StrCat("local subdivision: cell ", c, " is out of range [0, ", nc, ")"));
    }
    refined[c] = 1;
  }
  return refined;
}

// Split faces and edges belong to a refined cell (Split). Fine points are
// numbered after the coarse vertices: edge points, face points, then cell
// points.
Split SplitOf(const CellComplex& m, const std::vector<uint8_t>& refined) {
  const int32_t nv = m.num_vertices(), ne = m.num_edges(), nf = m.num_faces(),
                nc = m.num_cells();
  Split split;
  std::vector<int32_t>& edge_point = split.edge_point;
  std::vector<int32_t>& face_point = split.face_point;
  std::vector<int32_t>& cell_point = split.cell_point;
  std::vector<uint8_t>& edge_frozen = split.edge_frozen;
  std::vector<uint8_t>& face_frozen = split.face_frozen;
  std::vector<uint8_t>& vertex_frozen = split.vertex_frozen;
  edge_point.assign(ne, -1);
  face_point.assign(nf, -1);
  cell_point.assign(nc, -1);
  edge_frozen.assign(ne, 0);
  face_frozen.assign(nf, 0);
  vertex_frozen.assign(nv, 0);
  int32_t next = nv;
  for (int32_t e = 0; e < ne; ++e) {
    bool any = false, all = true;
    for (int32_t c : m.edge_cells(e)) {
      any |= refined[c] != 0;
      all &= refined[c] != 0;
    }
    if (any) edge_point[e] = next++;
    edge_frozen[e] = any && !all;
  }
  for (int32_t f = 0; f < nf; ++f) {
    const auto& fc = m.face_cells(f);
    const bool r0 = refined[fc[0]] != 0, r1 = fc[1] >= 0 && refined[fc[1]] != 0;
    if (r0 || r1) face_point[f] = next++;
    face_frozen[f] = (r0 || r1) && (!r0 || (fc[1] >= 0 && !r1));
  }
  for (int32_t c = 0; c < nc; ++c) {
    if (refined[c]) cell_point[c] = next++;
  }
  split.fine_vertices = next;
  for (int32_t v = 0; v < nv; ++v) {
    for (int32_t c : m.vertex_cells(v)) vertex_frozen[v] |= refined[c] == 0;
  }
  return split;
}

// The fine complex's face loops, and where each coarse face's and cell's
// fine faces start (FineFaceLoops).
struct FineFaces {
  Csr loops;
  // Per coarse face: its first child (split faces) or its one loop
  // (unsplit faces of a local subdivision); -1 otherwise.
  std::vector<int32_t> face_child, unsplit_face;
  // Per coarse cell: its first interior quad (refined cells), else -1.
  std::vector<int32_t> interior_base;
};

// Children of split faces: one quad per corner, in the parent's stored
// orientation.
void AddSplitFaceChildren(const CellComplex& m, const Split& split, FineFaces& out) {
  const int32_t nf = m.num_faces();
  Csr& loops = out.loops;
  for (int32_t f = 0; f < nf; ++f) {
    if (split.face_point[f] < 0) continue;
    out.face_child[f] = loops.rows();
    const auto loop = m.face_vertices(f);
    const auto edges = m.face_edges(f);
    const size_t k = loop.size();
    for (size_t i = 0; i < k; ++i) {
      const int32_t e_next = edges[i];
      const int32_t e_prev = edges[(i + k - 1) % k];
      loops.items.insert(loops.items.end(), {loop[i], split.edge_point[e_next],
                                             split.face_point[f], split.edge_point[e_prev]});
      loops.offsets.push_back(static_cast<int32_t>(loops.items.size()));
    }
  }
}

// Interior quads: one per refined cell and edge of that cell.
void AddInteriorQuads(const CellComplex& m, const Split& split,
                      const std::vector<uint8_t>& refined, FineFaces& out) {
  const int32_t nc = m.num_cells();
  const std::vector<int32_t>& edge_point = split.edge_point;
  const std::vector<int32_t>& face_point = split.face_point;
  Csr& loops = out.loops;
  std::vector<int32_t> fwd_face, bwd_face;  // per local edge of a cell
  for (int32_t c = 0; c < nc; ++c) {
    if (!refined[c]) continue;
    out.interior_base[c] = loops.rows();
    const auto cell_edges = m.cell_edges(c);
    fwd_face.assign(cell_edges.size(), -1);
    bwd_face.assign(cell_edges.size(), -1);
    const auto faces = m.cell_faces(c);
    const auto flip = m.cell_face_flipped(c);
    for (size_t k = 0; k < faces.size(); ++k) {
      const auto loop = m.face_vertices(faces[k]);
      const auto edges = m.face_edges(faces[k]);
      for (size_t i = 0; i < loop.size(); ++i) {
        const int32_t e = edges[i];
        const size_t j = static_cast<size_t>(
            std::lower_bound(cell_edges.begin(), cell_edges.end(), e) - cell_edges.begin());
        // Does the cell see this side going from edge_vertices[0] to [1]?
        const bool stored_fwd = loop[i] == m.edge_vertices(e)[0];
        const bool fwd = stored_fwd != (flip[k] != 0);
        (fwd ? fwd_face : bwd_face)[j] = faces[k];
      }
    }
    for (size_t j = 0; j < cell_edges.size(); ++j) {
      // Outward from the sub-cell at edge_vertices[0]: [F_fwd, E, F_bwd, C].
      loops.items.insert(loops.items.end(),
                         {face_point[fwd_face[j]], edge_point[cell_edges[j]],
                          face_point[bwd_face[j]], split.cell_point[c]});
      loops.offsets.push_back(static_cast<int32_t>(loops.items.size()));
    }
  }
}

// Unsplit faces (local subdivision) with split edges' points inserted.
void AddUnsplitFaces(const CellComplex& m, const Split& split, FineFaces& out) {
  const int32_t nf = m.num_faces();
  Csr& loops = out.loops;
  for (int32_t f = 0; f < nf; ++f) {
    if (split.face_point[f] >= 0) continue;
    out.unsplit_face[f] = loops.rows();
    const auto loop = m.face_vertices(f);
    const auto edges = m.face_edges(f);
    for (size_t i = 0; i < loop.size(); ++i) {
      loops.items.push_back(loop[i]);
      if (split.edge_point[edges[i]] >= 0) loops.items.push_back(split.edge_point[edges[i]]);
    }
    loops.offsets.push_back(static_cast<int32_t>(loops.items.size()));
  }
}

// Face ids: children of split faces (one quad per corner, in the parent's
// stored orientation), then interior quads (one per refined cell and
// edge of that cell), then unsplit faces with split edges' points inserted.
FineFaces FineFaceLoops(const CellComplex& m, const Split& split,
                        const std::vector<uint8_t>& refined, bool local) {
  const int32_t nf = m.num_faces(), nc = m.num_cells();
  FineFaces out;
  out.face_child.assign(nf, -1);
  out.unsplit_face.assign(nf, -1);
  out.interior_base.assign(nc, -1);
  out.loops.items.reserve(static_cast<size_t>(nf) * 16 + static_cast<size_t>(nc) * 48);
  AddSplitFaceChildren(m, split, out);
  AddInteriorQuads(m, split, refined, out);
  if (local) AddUnsplitFaces(m, split, out);
  return out;
}

// The fine complex's cells as faces (FineFaceLoops' ids) and whether each
// sees its face reversed.
struct FineCells {
  Csr cell_faces;
  std::vector<uint8_t> cell_flip;
};

// Cells: each refined cell gives one sub-cell per vertex (faces of the
// parent at that corner, interior quads of the parent's edges at it);
// each unrefined cell stays one cell with its split faces' children.
// Appends each fine cell's coarse cell to parent_cell.
FineCells FineCellFaces(const CellComplex& m, const std::vector<uint8_t>& refined,
                        const FineFaces& fine_faces, std::vector<int32_t>& parent_cell) {
  const int32_t nc = m.num_cells();
  const std::vector<int32_t>& face_child = fine_faces.face_child;
  const std::vector<int32_t>& unsplit_face = fine_faces.unsplit_face;
  const std::vector<int32_t>& interior_base = fine_faces.interior_base;
  FineCells out;
  Csr& cell_faces = out.cell_faces;
  std::vector<uint8_t>& cell_flip = out.cell_flip;
  cell_faces.items.reserve(static_cast<size_t>(nc) * 48);
  cell_flip.reserve(static_cast<size_t>(nc) * 48);
  std::vector<std::vector<std::pair<int32_t, uint8_t>>> corner;
  for (int32_t c = 0; c < nc; ++c) {
    const auto faces = m.cell_faces(c);
    const auto flip = m.cell_face_flipped(c);
    if (!refined[c]) {
      for (size_t k = 0; k < faces.size(); ++k) {
        const int32_t f = faces[k];
        if (face_child[f] >= 0) {
          for (int32_t i = 0; i < static_cast<int32_t>(m.face_edges(f).size()); ++i) {
            cell_faces.items.push_back(face_child[f] + i);
            cell_flip.push_back(flip[k]);
          }
        } else {
          cell_faces.items.push_back(unsplit_face[f]);
          cell_flip.push_back(flip[k]);
        }
      }
      cell_faces.offsets.push_back(static_cast<int32_t>(cell_faces.items.size()));
      parent_cell.push_back(c);
      continue;
    }
    const auto verts = m.cell_vertices(c);
    if (corner.size() < verts.size()) corner.resize(verts.size());
    for (size_t i = 0; i < verts.size(); ++i) corner[i].clear();
    auto local_vertex = [&](int32_t v) {
      return static_cast<size_t>(std::lower_bound(verts.begin(), verts.end(), v) -
                                 verts.begin());
    };
    for (size_t k = 0; k < faces.size(); ++k) {
      const auto loop = m.face_vertices(faces[k]);
      for (size_t i = 0; i < loop.size(); ++i) {
        corner[local_vertex(loop[i])].push_back(
            {face_child[faces[k]] + static_cast<int32_t>(i), flip[k]});
      }
    }
    const auto cell_edges = m.cell_edges(c);
    for (size_t j = 0; j < cell_edges.size(); ++j) {
      const auto& ev = m.edge_vertices(cell_edges[j]);
      const int32_t q = interior_base[c] + static_cast<int32_t>(j);
      corner[local_vertex(ev[0])].push_back({q, 0});
      corner[local_vertex(ev[1])].push_back({q, 1});
    }
    for (size_t i = 0; i < verts.size(); ++i) {
      for (const auto& [f, fl] : corner[i]) {
        cell_faces.items.push_back(f);
        cell_flip.push_back(fl);
      }
      cell_faces.offsets.push_back(static_cast<int32_t>(cell_faces.items.size()));
      parent_cell.push_back(c);
    }
  }
  return out;
}

// Sharp tags pass to both children of a split edge, or stay on an
// unsplit one. sharp_edges: the coarse edges' tags (empty: none).
std::vector<uint8_t> FineSharpEdges(const CellComplex& m, const std::vector<uint8_t>& sharp_edges,
                                    const std::vector<int32_t>& edge_point,
                                    const CellComplex& fine) {
  std::vector<uint8_t> fine_sharp(fine.num_edges(), 0);
  if (sharp_edges.empty()) return fine_sharp;
  const int32_t ne = m.num_edges();
  for (int32_t e = 0; e < ne; ++e) {
    if (sharp_edges[e] == 0) continue;
    const auto& ev = m.edge_vertices(e);
    if (edge_point[e] < 0) {
      fine_sharp[fine.FindEdge(ev[0], ev[1])] = 1;
    } else {
      fine_sharp[fine.FindEdge(ev[0], edge_point[e])] = 1;
      fine_sharp[fine.FindEdge(edge_point[e], ev[1])] = 1;
    }
  }
  return fine_sharp;
}

}  // namespace

// Coarse complexes of this many cells make their subdivision matrix on a
// second thread (the chair's 83 control cells: its first level 0.94 to
// 0.67-0.77 ms with the adjacency's threshold below).
constexpr int32_t kCellsForAThread = 64;

absl::StatusOr<Level> SubdivideOnce(const CellComplex& m, const SubdivisionOptions& options) {
  const int32_t ne = m.num_edges(), nc = m.num_cells();
  const bool has_sharp = !options.sharp_edges.empty();
  if (has_sharp && static_cast<int32_t>(options.sharp_edges.size()) != ne) {
    return absl::InvalidArgumentError(absl::StrCat(
        "sharp edge tags: got ", options.sharp_edges.size(), " for ", ne, " edges"));
  }

  // Which cells are refined (all, unless a subset is given).
  ASSIGN_OR_RETURN(const std::vector<uint8_t> refined, RefinedCells(nc, options.cells));
  const bool local = !options.cells.empty() &&
                     std::find(refined.begin(), refined.end(), 0) != refined.end();

  const Split split = SplitOf(m, refined);
  const int32_t nv_fine = split.fine_vertices;

  // The subdivision matrix and the fine positions are made from the coarse
  // complex alone: on a thread of their own beside the fine complex's
  // topology when the complex is large (the same result either way).
  Level level;
  Points fine_positions;
  auto matrix = [&] {
    level.a = SubdivisionMatrix(m, split, options.sharp_edges);
    fine_positions = level.a * m.positions();
  };
  std::thread beside;
  struct Join {
    std::thread& t;
    ~Join() {
      if (t.joinable()) t.join();
    }
  } join{beside};
  if (nc >= kCellsForAThread && !options.validate_geometry) {
    beside = std::thread(matrix);
  } else {
    matrix();
  }

  // ---- Topology of the fine complex. ----
  FineFaces faces = FineFaceLoops(m, split, refined, local);
  FineCells cells = FineCellFaces(m, refined, faces, level.parent_cell);

  // A fine cell is made of its parent's faces (split into children or
  // with split edges' points inserted) and, for a refined cell, interior
  // quads at its corner: closed and consistently oriented when its parent
  // is, and the coarse cells were checked when their complex was built
  // (FromInput, or an earlier level of closed parents). So closedness is
  // checked again only with the geometry (options.validate_geometry; the
  // tests check every level: tests/subdivision/mcj_test.cc).
  const bool check_closed = options.validate_geometry;
  if (beside.joinable()) {
    // Adjacency needs the vertex count only: the positions follow.
    ASSIGN_OR_RETURN(level.fine,
                     CellComplex::FromFaces(Points::Zero(nv_fine, 3), std::move(faces.loops),
                                            std::move(cells.cell_faces),
                                            std::move(cells.cell_flip),
                                            /*validate_geometry=*/false, check_closed));
    beside.join();
    level.fine.set_positions(std::move(fine_positions));
  } else {
    ASSIGN_OR_RETURN(level.fine, CellComplex::FromFaces(std::move(fine_positions),
                                                        std::move(faces.loops),
                                                        std::move(cells.cell_faces),
                                                        std::move(cells.cell_flip),
                                                        options.validate_geometry, check_closed));
  }

  level.sharp_edges = FineSharpEdges(m, options.sharp_edges, split.edge_point, level.fine);
  return level;
}

absl::StatusOr<Hierarchy> Subdivide(std::shared_ptr<const CellComplex> control, int levels,
                                    std::vector<uint8_t> control_sharp_edges,
                                    const std::function<void(const CellComplex&)>& beside_last) {
  if (levels < 0 || levels > 6) {
    return absl::InvalidArgumentError(
        absl::StrCat("subdivision levels must be in [0, 6], got ", levels));
  }
  Hierarchy h;
  h.control = control;
  h.fine = control;
  h.levels = levels;
  const int32_t n = control->num_vertices();
  h.a.resize(n, n);
  h.a.setIdentity();
  h.control_cell.resize(control->num_cells());
  for (int32_t c = 0; c < control->num_cells(); ++c) h.control_cell[c] = c;
  h.sharp_edges = control_sharp_edges.empty()
                      ? std::vector<uint8_t>(control->num_edges(), 0)
                      : std::move(control_sharp_edges);
  for (int l = 0; l < levels; ++l) {
    SubdivisionOptions options;
    options.sharp_edges = std::move(h.sharp_edges);
    ASSIGN_OR_RETURN(Level level, SubdivideOnce(*h.fine, options));
    for (int32_t& c : level.parent_cell) c = h.control_cell[c];
    h.control_cell = std::move(level.parent_cell);
    h.sharp_edges = std::move(level.sharp_edges);
    h.fine = std::make_shared<const CellComplex>(std::move(level.fine));
    if (l == 0) {
      h.a = std::move(level.a);
    } else if (l == levels - 1 && beside_last) {
      std::thread product([&] { h.a = MultiplyRowMajor(level.a, h.a); });
      beside_last(*h.fine);
      product.join();
    } else {
      h.a = MultiplyRowMajor(level.a, h.a);
    }
  }
  if (levels <= 1 && beside_last) beside_last(*h.fine);  // no product to run beside
  return h;
}

absl::StatusOr<std::vector<uint8_t>> SharpEdgesFromPairs(
    const CellComplex& complex, const std::vector<std::array<int32_t, 2>>& pairs) {
  std::vector<uint8_t> tags(complex.num_edges(), 0);
  for (size_t i = 0; i < pairs.size(); ++i) {
    const auto& [a, b] = pairs[i];
    const int32_t nv = complex.num_vertices();
    if (a < 0 || a >= nv || b < 0 || b >= nv) {
      return absl::InvalidArgumentError(absl::StrCat(
          "sharp edge ", i, " (", a, " ", b, "): vertex index out of range [0, ", nv, ")"));
    }
    const int32_t e = complex.FindEdge(a, b);
    if (e < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "sharp edge ", i, " (", a, " ", b, ") is not an edge of the control mesh"));
    }
    tags[e] = 1;
  }
  return tags;
}

void TagCreases(const CellComplex& complex, double degrees, std::vector<uint8_t>& tags) {
  tags.resize(complex.num_edges(), 0);
  if (degrees <= 0.0) return;
  const double cos_limit = std::cos(degrees * M_PI / 180.0);
  for (int32_t e = 0; e < complex.num_edges(); ++e) {
    if (!complex.edge_is_boundary(e)) continue;
    int32_t f[2];
    int k = 0;
    for (int32_t g : complex.edge_faces(e)) {
      if (complex.face_is_boundary(g)) {
        if (k < 2) f[k] = g;
        ++k;
      }
    }
    if (k != 2) continue;
    const Eigen::Vector3d n0 = FaceNormal(complex, f[0]).normalized();
    const Eigen::Vector3d n1 = FaceNormal(complex, f[1]).normalized();
    if (n0.dot(n1) < cos_limit) tags[e] = 1;
  }
}

}  // namespace dynsolid::subdivision
