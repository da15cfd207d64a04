#include "solver/mesh/cell_complex.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <thread>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/common/status_macros.h"

namespace dynsolid::mesh {
namespace {

std::string Prefix(const std::string& origin) {
  return origin.empty() ? std::string() : absl::StrCat(origin, ": ");
}

std::string LoopString(std::span<const int32_t> loop) {
  return absl::StrCat("(", absl::StrJoin(loop, " "), ")");
}

// True when `b` is `a` reversed (as cyclic sequences).
bool IsReversedLoop(std::span<const int32_t> a, std::span<const int32_t> b) {
  const size_t n = a.size();
  if (b.size() != n) return false;
  auto it = std::find(b.begin(), b.end(), a[0]);
  if (it == b.end()) return false;
  const size_t s = static_cast<size_t>(it - b.begin());
  for (size_t i = 0; i < n; ++i) {
    if (a[i] != b[(s + n - i) % n]) return false;
  }
  return true;
}

bool IsSameLoop(std::span<const int32_t> a, std::span<const int32_t> b) {
  const size_t n = a.size();
  if (b.size() != n) return false;
  auto it = std::find(b.begin(), b.end(), a[0]);
  if (it == b.end()) return false;
  const size_t s = static_cast<size_t>(it - b.begin());
  for (size_t i = 0; i < n; ++i) {
    if (a[i] != b[(s + i) % n]) return false;
  }
  return true;
}

// Inverts a relation given as CSR rows -> items in [0, num_targets).
Csr Invert(const Csr& rel, int32_t num_targets) {
  Csr inv;
  inv.offsets.assign(num_targets + 1, 0);
  for (int32_t x : rel.items) ++inv.offsets[x + 1];
  for (int32_t i = 0; i < num_targets; ++i) inv.offsets[i + 1] += inv.offsets[i];
  inv.items.resize(rel.items.size());
  std::vector<int32_t> fill(inv.offsets.begin(), inv.offsets.end() - 1);
  for (int32_t r = 0; r < rel.rows(); ++r) {
    for (int32_t x : rel.row(r)) inv.items[fill[x]++] = r;
  }
  return inv;
}

// Row r of the result: the sorted distinct items of inner's rows listed in
// outer's row r (e.g. cell -> faces composed with face -> vertices).
Csr ComposeUnique(const Csr& outer, const Csr& inner) {
  Csr out;
  out.offsets.reserve(outer.offsets.size());
  std::vector<int32_t> scratch;
  for (int32_t r = 0; r < outer.rows(); ++r) {
    scratch.clear();
    for (int32_t x : outer.row(r)) {
      const auto items = inner.row(x);
      scratch.insert(scratch.end(), items.begin(), items.end());
    }
    std::sort(scratch.begin(), scratch.end());
    scratch.erase(std::unique(scratch.begin(), scratch.end()), scratch.end());
    out.items.insert(out.items.end(), scratch.begin(), scratch.end());
    out.offsets.push_back(static_cast<int32_t>(out.items.size()));
  }
  return out;
}

// face -> cells from the cells' faces. Boundary faces are stored outward
// for their one cell: a face whose only user sees it reversed has its loop
// turned round in face_vertices and that use unflipped in
// cell_face_flipped.
absl::Status LinkFaceCells(const Csr& cell_faces, std::vector<uint8_t>& cell_face_flipped,
                           Csr& face_vertices, std::vector<std::array<int32_t, 2>>& face_cells) {
  const int32_t nf = face_vertices.rows();
  const int32_t nc = cell_faces.rows();
  face_cells.assign(nf, {-1, -1});
  for (int32_t c = 0; c < nc; ++c) {
    for (int32_t i = cell_faces.offsets[c]; i < cell_faces.offsets[c + 1]; ++i) {
      const int32_t f = cell_faces.items[i];
      if (f < 0 || f >= nf) {
        return absl::InvalidArgumentError(
            absl::StrCat("cell ", c, ": face index ", f, " out of range"));
      }
      const int slot = cell_face_flipped[i] ? 1 : 0;
      if (face_cells[f][slot] >= 0) {
        return absl::InvalidArgumentError(absl::StrCat(
            "face ", f, " ", LoopString(face_vertices.row(f)), " is used by cells ",
            face_cells[f][slot], " and ", c,
            " with the same orientation or by more than two cells"));
      }
      face_cells[f][slot] = c;
    }
  }
  for (int32_t f = 0; f < nf; ++f) {
    if (face_cells[f][0] >= 0) continue;
    if (face_cells[f][1] < 0) {
      return absl::InvalidArgumentError(absl::StrCat("face ", f, " belongs to no cell"));
    }
    // Only a reversed user: store the loop the other way round.
    const int32_t c = face_cells[f][1];
    auto* loop = face_vertices.items.data() + face_vertices.offsets[f];
    std::reverse(loop + 1, loop + face_vertices.row_size(f));
    face_cells[f] = {c, -1};
    for (int32_t i = cell_faces.offsets[c]; i < cell_faces.offsets[c + 1]; ++i) {
      if (cell_faces.items[i] == f) cell_face_flipped[i] = 0;
    }
  }
  return absl::OkStatus();
}

// Edges: bucket the loop sides by their smaller vertex, number them in
// (min, max) order so that ids are deterministic. Fills face -> edges
// (the same layout as the face loops) and the edges' end vertices.
absl::Status NumberEdges(const Csr& face_vertices, int32_t nv, Csr& face_edges,
                         std::vector<std::array<int32_t, 2>>& edge_vertices) {
  const int32_t nf = face_vertices.rows();
  const int64_t sides = static_cast<int64_t>(face_vertices.items.size());
  std::vector<int32_t> bucket(nv + 1, 0);
  for (int32_t f = 0; f < nf; ++f) {
    const auto loop = face_vertices.row(f);
    const size_t n = loop.size();
    for (size_t i = 0; i < n; ++i) {
      const int32_t a = loop[i], b = loop[(i + 1) % n];
      if (a < 0 || a >= nv) {
        return absl::InvalidArgumentError(
            absl::StrCat("face ", f, ": vertex index ", a, " out of range"));
      }
      ++bucket[std::min(a, b) + 1];
    }
  }
  for (int32_t v = 0; v < nv; ++v) bucket[v + 1] += bucket[v];
  std::vector<std::pair<int32_t, int32_t>> entries(sides);  // (max vertex, side)
  {
    std::vector<int32_t> fill(bucket.begin(), bucket.end() - 1);
    for (int32_t f = 0; f < nf; ++f) {
      const int32_t off = face_vertices.offsets[f];
      const auto loop = face_vertices.row(f);
      const size_t n = loop.size();
      for (size_t i = 0; i < n; ++i) {
        const int32_t a = loop[i], b = loop[(i + 1) % n];
        entries[fill[std::min(a, b)]++] = {std::max(a, b), off + static_cast<int32_t>(i)};
      }
    }
  }
  face_edges.offsets = face_vertices.offsets;
  face_edges.items.assign(sides, -1);
  edge_vertices.clear();
  for (int32_t v = 0; v < nv; ++v) {
    auto first = entries.begin() + bucket[v];
    auto last = entries.begin() + bucket[v + 1];
    std::sort(first, last);
    for (auto it = first; it != last; ++it) {
      if (it == first || it->first != (it - 1)->first) {
        edge_vertices.push_back({v, it->first});
      }
      face_edges.items[it->second] = static_cast<int32_t>(edge_vertices.size()) - 1;
    }
  }
  return absl::OkStatus();
}

// The cells of edges [e0, e1) in radial order, from one call of
// RadialOrder.
struct RadialCells {
  std::vector<int32_t> count, items;  // per edge of the range; its cells
};

// Radial order of edges [e0, e1): writes their faces in place into
// edge_faces_out.items (whose offsets are those of `edge_faces`, the
// unordered edge -> faces), marks boundary edges in edge_boundary, and
// lists their cells in `out`. Ranges that do not overlap may run at once.
void RadialOrder(const Csr& edge_faces, const std::vector<std::array<int32_t, 2>>& face_cells,
                 int32_t e0, int32_t e1, Csr& edge_faces_out,
                 std::vector<uint8_t>& edge_boundary, RadialCells& out) {
  out.count.assign(e1 - e0, 0);
  out.items.clear();
  out.items.reserve(edge_faces.offsets[e1] - edge_faces.offsets[e0]);
  // Per face of the edge (its slot in the edge's face list): its two
  // cells and whether the walk has passed it.
  std::vector<int32_t> cell0, cell1;
  std::vector<uint8_t> used;
  for (int32_t e = e0; e < e1; ++e) {
    const auto faces = edge_faces.row(e);
    const int k = static_cast<int>(faces.size());
    const size_t cells_before = out.items.size();
    cell0.resize(k);
    cell1.resize(k);
    used.assign(k, 0);
    for (int i = 0; i < k; ++i) {
      cell0[i] = face_cells[faces[i]][0];
      cell1[i] = face_cells[faces[i]][1];
      if (cell1[i] < 0) edge_boundary[e] = 1;
    }
    int32_t at = edge_faces_out.offsets[e];
    // Walk face -> cell -> the cell's other face at e, from boundary faces
    // first, then from any face left (interior edges).
    while (true) {
      int start = -1;
      for (int i = 0; i < k && start < 0; ++i) {
        if (!used[i] && cell1[i] < 0) start = i;
      }
      for (int i = 0; i < k && start < 0; ++i) {
        if (!used[i]) start = i;
      }
      if (start < 0) break;
      int i = start;
      int32_t prev_cell = -1;
      while (true) {
        used[i] = 1;
        edge_faces_out.items[at++] = faces[i];
        int32_t cell = -1;
        if (cell0[i] >= 0 && cell0[i] != prev_cell) {
          cell = cell0[i];
        } else if (cell1[i] >= 0 && cell1[i] != prev_cell) {
          cell = cell1[i];
        }
        if (cell < 0) break;
        // The first other face of the edge on that cell.
        int next = -1;
        for (int j = 0; j < k && next < 0; ++j) {
          if (j != i && (cell0[j] == cell || cell1[j] == cell)) next = j;
        }
        if (next < 0) break;  // open cell: reported by CheckCellsClosed
        out.items.push_back(cell);
        if (used[next]) break;
        prev_cell = cell;
        i = next;
      }
    }
    out.count[e - e0] = static_cast<int32_t>(out.items.size() - cells_before);
  }
}

// Vertex -> edges: the edges as rows of their two vertices, inverted.
Csr VertexEdges(const std::vector<std::array<int32_t, 2>>& edge_vertices, int32_t nv) {
  const int32_t ne = static_cast<int32_t>(edge_vertices.size());
  Csr edge_rows;
  edge_rows.offsets.resize(ne + 1);
  edge_rows.items.resize(2 * static_cast<size_t>(ne));
  for (int32_t e = 0; e < ne; ++e) {
    edge_rows.offsets[e + 1] = 2 * (e + 1);
    edge_rows.items[2 * e] = edge_vertices[e][0];
    edge_rows.items[2 * e + 1] = edge_vertices[e][1];
  }
  return Invert(edge_rows, nv);
}

}  // namespace

int32_t DropUnusedVertices(MeshInput& input) {
  const int32_t nv = static_cast<int32_t>(input.vertices.rows());
  std::vector<int32_t> remap(nv, -1);
  for (const auto& cell : input.cells)
    for (const auto& loop : cell)
      for (int32_t v : loop)
        if (v >= 0 && v < nv) remap[v] = 0;
  int32_t used = 0;
  for (int32_t v = 0; v < nv; ++v) {
    if (remap[v] < 0) continue;
    if (used != v) input.vertices.row(used) = input.vertices.row(v);
    remap[v] = used++;
  }
  if (used == nv) return 0;
  input.vertices.conservativeResize(used, 3);
  for (auto& cell : input.cells)
    for (auto& loop : cell)
      for (int32_t& v : loop)
        if (v >= 0 && v < nv) v = remap[v];
  return nv - used;
}

absl::StatusOr<CellComplex> CellComplex::FromInput(const MeshInput& input) {
  const std::string pre = Prefix(input.origin);
  const int32_t nv = static_cast<int32_t>(input.vertices.rows());
  if (nv == 0) return absl::InvalidArgumentError(pre + "mesh has no vertices");
  if (input.cells.empty()) return absl::InvalidArgumentError(pre + "mesh has no cells");
  static constexpr const char* kAxis[3] = {"x", "y", "z"};
  for (int32_t v = 0; v < nv; ++v) {
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(input.vertices(v, k))) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "vertex ", v, " has a non-finite coordinate ", kAxis[k], " = ",
            input.vertices(v, k)));
      }
    }
  }

  // Identify faces by their sorted vertex sets; the first cell's loop is the
  // stored one.
  Csr face_loops;
  Csr cell_faces;
  std::vector<uint8_t> flipped;
  std::map<std::vector<int32_t>, int32_t> face_index;
  std::vector<std::array<int32_t, 3>> face_users;  // cells using each face
  std::vector<int32_t> key;
  for (size_t c = 0; c < input.cells.size(); ++c) {
    const auto& faces = input.cells[c];
    if (faces.size() < 4) {
      return absl::InvalidArgumentError(absl::StrCat(
          pre, "cell ", c, " has ", faces.size(),
          " faces; a closed cell needs at least 4"));
    }
    for (size_t k = 0; k < faces.size(); ++k) {
      const auto& loop = faces[k];
      if (loop.size() < 3) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "cell ", c, " face ", k, " has ", loop.size(),
            " vertices; a face needs at least 3"));
      }
      for (int32_t v : loop) {
        if (v < 0 || v >= nv) {
          return absl::InvalidArgumentError(absl::StrCat(
              pre, "cell ", c, " face ", k, ": vertex index ", v,
              " is out of range [0, ", nv, ")"));
        }
      }
      key.assign(loop.begin(), loop.end());
      std::sort(key.begin(), key.end());
      if (std::adjacent_find(key.begin(), key.end()) != key.end()) {
        const int32_t rep = *std::adjacent_find(key.begin(), key.end());
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "cell ", c, " face ", k, ": vertex ", rep,
            " is repeated in the face loop ", LoopString(loop)));
      }
      auto [it, inserted] = face_index.try_emplace(key, face_loops.rows());
      const int32_t f = it->second;
      if (inserted) {
        face_loops.items.insert(face_loops.items.end(), loop.begin(), loop.end());
        face_loops.offsets.push_back(static_cast<int32_t>(face_loops.items.size()));
        face_users.push_back({static_cast<int32_t>(c), -1, -1});
        cell_faces.items.push_back(f);
        flipped.push_back(0);
        continue;
      }
      auto& users = face_users[f];
      if (users[0] == static_cast<int32_t>(c) || users[1] == static_cast<int32_t>(c)) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "cell ", c, " lists face ", LoopString(loop), " twice"));
      }
      if (users[1] >= 0) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "face ", LoopString(loop), " is shared by cells ", users[0], ", ",
            users[1], " and ", c, "; a face belongs to at most two cells"));
      }
      users[1] = static_cast<int32_t>(c);
      const auto stored = face_loops.row(f);
      if (IsSameLoop(stored, loop)) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "inconsistent orientation: cells ", users[0], " and ", c,
            " share face ", LoopString(loop),
            " with the same loop direction; an interior face needs opposite "
            "loops (each oriented outward from its cell)"));
      }
      if (!IsReversedLoop(stored, loop)) {
        return absl::InvalidArgumentError(absl::StrCat(
            pre, "cells ", users[0], " and ", c, " list face ", LoopString(stored),
            " with different vertex orders (", LoopString(loop), ")"));
      }
      cell_faces.items.push_back(f);
      flipped.push_back(1);
    }
    cell_faces.offsets.push_back(static_cast<int32_t>(cell_faces.items.size()));
  }

  std::vector<uint8_t> used(nv, 0);
  for (int32_t v : face_loops.items) used[v] = 1;
  for (int32_t v = 0; v < nv; ++v) {
    if (!used[v]) {
      return absl::InvalidArgumentError(absl::StrCat(
          pre, "vertex ", v, " belongs to no cell; remove unused vertices"));
    }
  }

  absl::StatusOr<CellComplex> result = FromFaces(
      input.vertices, std::move(face_loops), std::move(cell_faces), std::move(flipped),
      /*validate_geometry=*/true);
  if (!result.ok() && !pre.empty()) {
    return absl::Status(result.status().code(),
                        absl::StrCat(pre, result.status().message()));
  }
  return result;
}

absl::StatusOr<CellComplex> CellComplex::FromFaces(Points vertices, Csr face_loops,
                                                   Csr cell_faces,
                                                   std::vector<uint8_t> cell_face_flipped,
                                                   bool validate_geometry, bool check_closed) {
  CellComplex m;
  m.positions_ = std::move(vertices);
  m.face_vertices_ = std::move(face_loops);
  m.cell_faces_ = std::move(cell_faces);
  m.cell_face_flipped_ = std::move(cell_face_flipped);
  if (m.cell_face_flipped_.size() != m.cell_faces_.items.size()) {
    return absl::InternalError("cell_face_flipped does not match cell_faces");
  }
  RETURN_IF_ERROR(m.BuildAdjacency(check_closed));
  if (validate_geometry) RETURN_IF_ERROR(m.CheckVolumes(""));
  return m;
}

absl::Status CellComplex::BuildAdjacency(bool check_closed) {
  const int32_t nv = num_vertices();
  const int32_t nf = num_faces();
  const int32_t nc = num_cells();

  // face -> cells. Boundary faces are stored outward for their one cell.
  RETURN_IF_ERROR(LinkFaceCells(cell_faces_, cell_face_flipped_, face_vertices_, face_cells_));

  // Edges, numbered in (min, max) vertex order.
  RETURN_IF_ERROR(NumberEdges(face_vertices_, nv, face_edges_, edge_vertices_));
  const int32_t ne = num_edges();

  // Edge -> faces (unordered first), then radial order with cells, edges
  // [e0, e1) at a time: each range writes its edges' faces in place and
  // their cells to a list of its own, joined in edge order below.
  const Csr edge_faces = Invert(face_edges_, ne);
  edge_faces_.offsets = edge_faces.offsets;
  edge_faces_.items.resize(edge_faces.items.size());
  edge_boundary_.assign(ne, 0);
  auto radial = [this, &edge_faces](int32_t e0, int32_t e1, RadialCells& out) {
    RadialOrder(edge_faces, face_cells_, e0, e1, edge_faces_, edge_boundary_, out);
  };

  // The rest reads the faces' edges and writes members of its own. The
  // cells' closedness check, their edges, the vertices' faces and which
  // vertices are on the boundary run beside it on a thread of their own
  // when the complex is large (a subdivision's finest level); where there
  // is no check, that thread also takes the first half of the edges'
  // radial order (the two threads' shares then about even): the same
  // result either way.
  const int32_t split = check_closed ? 0 : ne / 2;
  RadialCells first, second;
  absl::Status closed;
  auto side = [this, &closed, check_closed, &radial, split, &first, nv, nf] {
    if (check_closed) closed = CheckCellsClosed();
    cell_edges_ = ComposeUnique(cell_faces_, face_edges_);
    vertex_faces_ = Invert(face_vertices_, nv);
    vertex_boundary_.assign(nv, 0);
    for (int32_t f = 0; f < nf; ++f) {
      if (face_cells_[f][1] >= 0) continue;
      for (int32_t v : face_vertices_.row(f)) vertex_boundary_[v] = 1;
    }
    radial(0, split, first);
  };
  std::thread beside;
  if (nc >= kCellsForAThread) {
    beside = std::thread(side);
  } else {
    side();
  }

  // Cells -> vertices (and edges, above), sorted, unique.
  cell_vertices_ = ComposeUnique(cell_faces_, face_vertices_);

  // Vertex -> edges, faces, cells.
  vertex_edges_ = VertexEdges(edge_vertices_, nv);
  vertex_cells_ = Invert(cell_vertices_, nv);
  radial(split, ne, second);
  if (beside.joinable()) beside.join();
  edge_cells_.offsets.assign(ne + 1, 0);
  for (int32_t e = 0; e < ne; ++e) {
    edge_cells_.offsets[e + 1] =
        edge_cells_.offsets[e] + (e < split ? first.count[e] : second.count[e - split]);
  }
  edge_cells_.items = std::move(first.items);
  edge_cells_.items.insert(edge_cells_.items.end(), second.items.begin(), second.items.end());
  return closed;
}

absl::Status CellComplex::CheckCellsClosed() const {
  // Every edge of a cell lies in exactly two of its faces, traversed in
  // opposite directions (a closed, consistently oriented polyhedron).
  std::vector<std::array<int32_t, 3>> sides;  // (edge, direction, face)
  for (int32_t c = 0; c < num_cells(); ++c) {
    sides.clear();
    const auto faces = cell_faces(c);
    const auto flip = cell_face_flipped(c);
    for (size_t k = 0; k < faces.size(); ++k) {
      const auto loop = face_vertices(faces[k]);
      const auto edges = face_edges(faces[k]);
      const size_t n = loop.size();
      for (size_t i = 0; i < n; ++i) {
        const int32_t a = loop[i], b = loop[(i + 1) % n];
        int dir = a < b ? 1 : 0;
        if (flip[k]) dir = 1 - dir;
        sides.push_back({edges[i], dir, static_cast<int32_t>(k)});
      }
    }
    std::sort(sides.begin(), sides.end());
    size_t i = 0;
    while (i < sides.size()) {
      size_t j = i;
      while (j < sides.size() && sides[j][0] == sides[i][0]) ++j;
      const auto& ev = edge_vertices_[sides[i][0]];
      if (j - i != 2) {
        return absl::InvalidArgumentError(absl::StrCat(
            "cell ", c, " is not closed: edge (", ev[0], " ", ev[1], ") lies in ", j - i,
            " of its faces; every edge of a cell must lie in exactly two"));
      }
      if (sides[i][1] == sides[i + 1][1]) {
        return absl::InvalidArgumentError(absl::StrCat(
            "inconsistent orientation: cell ", c, " faces ", sides[i][2], " and ",
            sides[i + 1][2], " traverse edge (", ev[0], " ", ev[1],
            ") in the same direction; face loops must all be outward"));
      }
      i = j;
    }
  }
  return absl::OkStatus();
}

absl::Status CellComplex::CheckVolumes(const std::string& origin) const {
  for (int32_t c = 0; c < num_cells(); ++c) {
    const double vol = CellVolume(c);
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY);
    Eigen::Vector3d hi = -lo;
    for (int32_t v : cell_vertices(c)) {
      lo = lo.cwiseMin(positions_.row(v).transpose());
      hi = hi.cwiseMax(positions_.row(v).transpose());
    }
    const double size = (hi - lo).maxCoeff();
    const double tiny = 1e-12 * size * size * size;
    if (vol <= tiny) {
      return absl::InvalidArgumentError(absl::StrCat(
          Prefix(origin), "cell ", c, " has ", vol < -tiny ? "negative" : "zero",
          " volume ", vol, " (size ", size,
          "); cells must have positive volume with outward face loops"));
    }
  }
  return absl::OkStatus();
}

void CellComplex::CellFaceLoop(int32_t c, int32_t local_face, std::vector<int32_t>& out) const {
  const int32_t i = cell_faces_.offsets[c] + local_face;
  const auto loop = face_vertices(cell_faces_.items[i]);
  out.assign(loop.begin(), loop.end());
  if (cell_face_flipped_[i]) std::reverse(out.begin() + 1, out.end());
}

int32_t CellComplex::FindEdge(int32_t a, int32_t b) const {
  for (int32_t e : vertex_edges(a)) {
    const auto& ev = edge_vertices_[e];
    if ((ev[0] == a && ev[1] == b) || (ev[0] == b && ev[1] == a)) return e;
  }
  return -1;
}

Eigen::Vector3d CellComplex::FaceCentroid(int32_t f) const {
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  const auto loop = face_vertices(f);
  for (int32_t v : loop) s += positions_.row(v).transpose();
  return s / static_cast<double>(loop.size());
}

Eigen::Vector3d CellComplex::CellCentroid(int32_t c) const {
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  const auto verts = cell_vertices(c);
  for (int32_t v : verts) s += positions_.row(v).transpose();
  return s / static_cast<double>(verts.size());
}

double CellComplex::CellVolume(int32_t c) const {
  // Divergence theorem over faces fanned from their centroids, relative to
  // the cell centroid for accuracy.
  const Eigen::Vector3d o = CellCentroid(c);
  double six_v = 0.0;
  const auto faces = cell_faces(c);
  const auto flip = cell_face_flipped(c);
  for (size_t k = 0; k < faces.size(); ++k) {
    const auto loop = face_vertices(faces[k]);
    const Eigen::Vector3d fc = FaceCentroid(faces[k]) - o;
    const size_t n = loop.size();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d a = positions_.row(loop[i]).transpose() - o;
      const Eigen::Vector3d b = positions_.row(loop[(i + 1) % n]).transpose() - o;
      const double t = fc.dot(a.cross(b));
      six_v += flip[k] ? -t : t;
    }
  }
  return six_v / 6.0;
}

bool CellComplex::CellIsHexahedron(int32_t c) const {
  if (cell_faces_.row_size(c) != 6 || cell_vertices_.row_size(c) != 8 ||
      cell_edges_.row_size(c) != 12) {
    return false;
  }
  for (int32_t f : cell_faces(c)) {
    if (face_vertices_.row_size(f) != 4) return false;
  }
  return true;
}

CellComplex::BoundaryCounts CellComplex::CountBoundary() const {
  BoundaryCounts b;
  for (int32_t f = 0; f < num_faces(); ++f) b.faces += face_is_boundary(f) ? 1 : 0;
  for (int32_t e = 0; e < num_edges(); ++e) b.edges += edge_boundary_[e];
  for (int32_t v = 0; v < num_vertices(); ++v) b.vertices += vertex_boundary_[v];
  return b;
}

}  // namespace dynsolid::mesh
