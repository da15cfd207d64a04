#include "solver/fem/element_set.h"

#include <algorithm>
#include <array>

#include "solver/common/parallel.h"

namespace dynsolid::fem {
namespace {

using mesh::CellComplex;

// VTK hexahedron corner i sits at parametric (u, v, w) = kHexCorner[i].
constexpr int kHexCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                  {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

int32_t OtherEnd(const CellComplex& m, int32_t e, int32_t v) {
  const auto& ev = m.edge_vertices(e);
  return ev[0] == v ? ev[1] : ev[0];
}

bool LoopContains(std::span<const int32_t> loop, int32_t v) {
  return std::find(loop.begin(), loop.end(), v) != loop.end();
}

// Corners of hexahedral cell c in VTK order: the first face, reversed so its
// normal points into the cell, then the vertex across the edge leaving
// each of its corners.
// bottom: scratch (kept by the caller from cell to cell).
std::array<int32_t, 8> HexCorners(const CellComplex& m, int32_t c, std::vector<int32_t>& bottom) {
  std::array<int32_t, 8> h{};
  m.CellFaceLoop(c, 0, bottom);
  std::reverse(bottom.begin() + 1, bottom.end());
  for (int i = 0; i < 4; ++i) h[i] = bottom[i];
  for (int i = 0; i < 4; ++i) {
    for (int32_t e : m.cell_edges(c)) {
      const auto& ev = m.edge_vertices(e);
      if (ev[0] != h[i] && ev[1] != h[i]) continue;
      const int32_t w = OtherEnd(m, e, h[i]);
      if (!LoopContains(bottom, w)) {
        h[4 + i] = w;
        break;
      }
    }
  }
  return h;
}

// A vertex around which a cubic element may sit: interior, 6 edges and 8
// hexahedral cells (the regular grid's vertex star).
std::vector<uint8_t> RegularVertices(const CellComplex& m, const std::vector<uint8_t>& is_hex) {
  std::vector<uint8_t> regular(m.num_vertices(), 0);
  for (int32_t v = 0; v < m.num_vertices(); ++v) {
    if (m.vertex_is_boundary(v) || m.vertex_edges(v).size() != 6 ||
        m.vertex_cells(v).size() != 8) {
      continue;
    }
    bool all_hex = true;
    for (int32_t c : m.vertex_cells(v)) all_hex &= is_hex[c] != 0;
    regular[v] = all_hex;
  }
  return regular;
}

// The star of a regular vertex x, made once per vertex (a regular vertex
// is a corner of 8 cells, each asking for it): for each of its 12 quad
// faces, the loop neighbours of x (prev, next) and the vertex across the
// face from x; and for each of its 6 edge neighbours, the one opposite.
struct Star {
  std::array<std::array<int32_t, 3>, 12> faces;  // {prev, next, diagonal}
  std::array<std::array<int32_t, 2>, 6> opposite;  // {neighbour, the one opposite it}
  int count = 0;

  Star() = default;
  Star(const CellComplex& m, int32_t x) {
    for (int32_t f : m.vertex_faces(x)) {
      const auto loop = m.face_vertices(f);
      if (loop.size() != 4 || count == 12) continue;
      const size_t i = static_cast<size_t>(std::find(loop.begin(), loop.end(), x) - loop.begin());
      faces[count++] = {loop[(i + 3) % 4], loop[(i + 1) % 4], loop[(i + 2) % 4]};
    }
    // The edge neighbour of x opposite y: the first on no face with x and y.
    const auto edges = m.vertex_edges(x);
    for (size_t k = 0; k < 6; ++k) {
      const int32_t y = OtherEnd(m, edges[k], x);
      int32_t opp = -1;
      for (int32_t e : edges) {
        const int32_t n = OtherEnd(m, e, x);
        if (n != y && !ShareFace(n, y)) {
          opp = n;
          break;
        }
      }
      opposite[k] = {y, opp};
    }
  }
  bool ShareFace(int32_t a, int32_t b) const { return Diagonal(a, b) >= 0; }
  // The vertex across the face containing x, a and b, or -1.
  int32_t Diagonal(int32_t a, int32_t b) const {
    for (int k = 0; k < count; ++k) {
      const auto& t = faces[k];
      if ((t[0] == a && t[1] == b) || (t[0] == b && t[1] == a)) return t[2];
    }
    return -1;
  }
  // The edge neighbour of x opposite its edge neighbour y, or -1.
  int32_t Opposite(int32_t y) const {
    for (const auto& [n, opp] : opposite) {
      if (n == y) return opp;
    }
    return -1;
  }
};

// The stars of the regular vertices (by vertex; others left empty), made
// on a few threads.
std::vector<Star> RegularStars(const CellComplex& m, const std::vector<uint8_t>& regular) {
  std::vector<Star> stars(m.num_vertices());
  ParallelParts(m.num_vertices(), BuildThreads(), 16, 1024, [&](int, int, int64_t b, int64_t e) {
    for (int64_t v = b; v < e; ++v) {
      if (regular[v]) stars[v] = Star(m, static_cast<int32_t>(v));
    }
  });
  return stars;
}

// The hexahedron around x containing a, b and d: its eighth vertex, the one
// not in `known` (x, a, b, d and the three face diagonals).
int32_t HexOpposite(const CellComplex& m, int32_t x, int32_t a, int32_t b, int32_t d,
                    const std::array<int32_t, 7>& known) {
  for (int32_t c : m.vertex_cells(x)) {
    const auto verts = m.cell_vertices(c);
    if (!std::binary_search(verts.begin(), verts.end(), a) ||
        !std::binary_search(verts.begin(), verts.end(), b) ||
        !std::binary_search(verts.begin(), verts.end(), d)) {
      continue;
    }
    for (int32_t v : verts) {
      if (std::find(known.begin(), known.end(), v) == known.end()) return v;
    }
  }
  return -1;
}

// 64 nodes of a regular hexahedron in tensor order m = 16 i + 4 j + k.
std::array<int32_t, 64> CubicNodes(const CellComplex& m, const std::vector<Star>& stars,
                                   const std::array<int32_t, 8>& h) {
  std::array<int32_t, 64> nodes;
  nodes.fill(-1);
  auto at = [&](int i, int j, int k) -> int32_t& { return nodes[16 * i + 4 * j + k]; };
  for (int n = 0; n < 8; ++n) {
    const int u = kHexCorner[n][0], v = kHexCorner[n][1], w = kHexCorner[n][2];
    const int32_t x = h[n];
    const Star& star = stars[x];
    // Outward step along each axis: across the edge opposite the in-cell one.
    std::array<int32_t, 3> out{};
    for (int axis = 0; axis < 3; ++axis) {
      int nb[3] = {u, v, w};
      nb[axis] = 1 - nb[axis];
      int32_t inside = -1;
      for (int q = 0; q < 8; ++q) {
        if (kHexCorner[q][0] == nb[0] && kHexCorner[q][1] == nb[1] && kHexCorner[q][2] == nb[2]) {
          inside = h[q];
        }
      }
      out[axis] = star.Opposite(inside);
    }
    const int I = 1 + u, J = 1 + v, K = 1 + w;
    const int Io = u ? 3 : 0, Jo = v ? 3 : 0, Ko = w ? 3 : 0;
    at(I, J, K) = x;
    at(Io, J, K) = out[0];
    at(I, Jo, K) = out[1];
    at(I, J, Ko) = out[2];
    at(Io, Jo, K) = star.Diagonal(out[0], out[1]);
    at(Io, J, Ko) = star.Diagonal(out[0], out[2]);
    at(I, Jo, Ko) = star.Diagonal(out[1], out[2]);
    at(Io, Jo, Ko) = HexOpposite(m, x, out[0], out[1], out[2],
                                 {x, out[0], out[1], out[2], at(Io, Jo, K), at(Io, J, Ko),
                                  at(I, Jo, Ko)});
  }
  return nodes;
}

}  // namespace

namespace {

// Classifies cells [begin, end). Virtual nodes are numbered from 0 within
// the chunk; ClassifyElements offsets them when joining chunks.
void ClassifyRange(const CellComplex& m, const std::vector<uint8_t>& is_hex,
                   const std::vector<uint8_t>& regular, const std::vector<Star>& stars,
                   int32_t begin, int32_t end, ElementSet& s) {
  std::vector<int32_t> loop;
  for (int32_t c = begin; c < end; ++c) {
    if (is_hex[c]) {
      const std::array<int32_t, 8> h = HexCorners(m, c, loop);
      bool cubic = true;
      for (int32_t v : h) cubic &= regular[v] != 0;
      if (cubic) {
        const std::array<int32_t, 64> nodes = CubicNodes(m, stars, h);
        if (std::find(nodes.begin(), nodes.end(), -1) == nodes.end()) {
          s.cubic_nodes.insert(s.cubic_nodes.end(), nodes.begin(), nodes.end());
          s.cubic_cell.push_back(c);
          continue;
        }
      }
      s.linear_nodes.insert(s.linear_nodes.end(), h.begin(), h.end());
      s.linear_cell.push_back(c);
      continue;
    }
    // Irregular cell: a virtual centre node and one pyramid per face.
    const int32_t apex = s.num_virtual_nodes++;
    s.virtual_node_cell.push_back(c);
    const int32_t nfaces = static_cast<int32_t>(m.cell_faces(c).size());
    for (int32_t k = 0; k < nfaces; ++k) {
      m.CellFaceLoop(c, k, loop);  // outward; the pyramid base points inward
      auto add = [&](int32_t a, int32_t b, int32_t cc, int32_t d) {
        s.pyramid_nodes.insert(s.pyramid_nodes.end(), {a, b, cc, d, apex});
        s.pyramid_cell.push_back(c);
      };
      if (loop.size() == 4) {
        add(loop[0], loop[3], loop[2], loop[1]);
      } else {
        for (size_t i = 1; i + 1 < loop.size(); ++i) {
          add(loop[0], loop[i + 1], loop[i], loop[i]);
        }
      }
    }
  }
}

template <typename T>
void Append(std::vector<T>& to, const std::vector<T>& from) {
  to.insert(to.end(), from.begin(), from.end());
}

}  // namespace

ElementSet ClassifyElements(const CellComplex& m) {
  const int32_t nc = m.num_cells();
  std::vector<uint8_t> is_hex(nc);
  for (int32_t c = 0; c < nc; ++c) is_hex[c] = m.CellIsHexahedron(c);
  // Interior faces, 26 hexahedral neighbours and valence-6 corners all
  // follow from the 8 corners being regular vertices.
  const std::vector<uint8_t> regular = RegularVertices(m, is_hex);
  const std::vector<Star> stars = RegularStars(m, regular);

  // Cells in contiguous chunks on a few threads, joined in chunk order: the
  // result does not depend on the number of threads.
  // (Parts of 512 cells or more, taken by whichever thread is free: the
  // last level's matrix product runs beside this.)
  std::vector<ElementSet> parts(16);
  const int chunks = ParallelParts(nc, BuildThreads(), static_cast<int>(parts.size()), 512,
                                   [&](int, int k, int64_t b, int64_t e) {
                                     ClassifyRange(m, is_hex, regular, stars,
                                                   static_cast<int32_t>(b),
                                                   static_cast<int32_t>(e), parts[k]);
                                   });
  ElementSet s;
  s.num_mesh_vertices = m.num_vertices();
  size_t cubic = 0, linear = 0, pyramid = 0;
  for (int k = 0; k < chunks; ++k) {
    cubic += parts[k].cubic_nodes.size();
    linear += parts[k].linear_nodes.size();
    pyramid += parts[k].pyramid_nodes.size();
  }
  s.cubic_nodes.reserve(cubic);
  s.linear_nodes.reserve(linear);
  s.pyramid_nodes.reserve(pyramid);
  for (int k = 0; k < chunks; ++k) {
    ElementSet& p = parts[k];
    const int32_t first_virtual = s.num_mesh_vertices + s.num_virtual_nodes;
    for (size_t i = 4; i < p.pyramid_nodes.size(); i += 5) p.pyramid_nodes[i] += first_virtual;
    Append(s.cubic_nodes, p.cubic_nodes);
    Append(s.cubic_cell, p.cubic_cell);
    Append(s.linear_nodes, p.linear_nodes);
    Append(s.linear_cell, p.linear_cell);
    Append(s.pyramid_nodes, p.pyramid_nodes);
    Append(s.pyramid_cell, p.pyramid_cell);
    Append(s.virtual_node_cell, p.virtual_node_cell);
    s.num_virtual_nodes += p.num_virtual_nodes;
    p = ElementSet();
  }
  return s;
}

subdivision::SparseMatrix NodeMatrix(const CellComplex& m, const subdivision::SparseMatrix& a,
                                     const ElementSet& elements) {
  if (elements.num_virtual_nodes == 0) return a;
  if (!a.isCompressed()) {
    subdivision::SparseMatrix compressed = a;
    compressed.makeCompressed();
    return NodeMatrix(m, compressed, elements);
  }
  // S A with S = [I; V], V the virtual nodes' rows of their cells' vertex
  // means: A's rows as they are (the product's row of an identity row is
  // that row, bit for bit: one term times 1), copied; then V A.
  std::vector<int32_t> outer{0}, inner;
  std::vector<double> values;
  for (int32_t i = 0; i < elements.num_virtual_nodes; ++i) {
    const auto verts = m.cell_vertices(elements.virtual_node_cell[i]);  // ascending
    for (int32_t v : verts) {
      inner.push_back(v);
      values.push_back(1.0 / static_cast<double>(verts.size()));
    }
    outer.push_back(static_cast<int32_t>(inner.size()));
  }
  const subdivision::SparseMatrix v = subdivision::MultiplyRowMajor(
      subdivision::FromCsr(elements.num_virtual_nodes, static_cast<int32_t>(a.rows()), outer,
                           inner, values),
      a);
  const Eigen::Index rows = a.rows(), nnz = a.nonZeros();
  subdivision::SparseMatrix out(elements.num_nodes(), a.cols());
  out.resizeNonZeros(nnz + v.nonZeros());
  std::copy(a.outerIndexPtr(), a.outerIndexPtr() + rows + 1, out.outerIndexPtr());
  for (Eigen::Index r = 1; r <= v.rows(); ++r) {
    out.outerIndexPtr()[rows + r] = static_cast<int32_t>(nnz) + v.outerIndexPtr()[r];
  }
  std::copy(a.innerIndexPtr(), a.innerIndexPtr() + nnz, out.innerIndexPtr());
  std::copy(a.valuePtr(), a.valuePtr() + nnz, out.valuePtr());
  std::copy(v.innerIndexPtr(), v.innerIndexPtr() + v.nonZeros(), out.innerIndexPtr() + nnz);
  std::copy(v.valuePtr(), v.valuePtr() + v.nonZeros(), out.valuePtr() + nnz);
  return out;
}

}  // namespace dynsolid::fem
