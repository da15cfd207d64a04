#include "solver/fem/element_set.h"

#include <algorithm>
#include <array>

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
std::array<int32_t, 8> HexCorners(const CellComplex& m, int32_t c) {
  std::array<int32_t, 8> h{};
  std::vector<int32_t> bottom;
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

// The cubic B-spline element conditions of MODEL.md section 3.
bool IsRegularHex(const CellComplex& m, int32_t c) {
  for (int32_t f : m.cell_faces(c)) {
    if (m.face_is_boundary(f)) return false;
  }
  std::array<int32_t, 27> nbrs{};
  int count = 0;
  for (int32_t v : m.cell_vertices(c)) {
    if (m.vertex_is_boundary(v) || m.vertex_edges(v).size() != 6 ||
        m.vertex_cells(v).size() != 8) {
      return false;
    }
    for (int32_t n : m.vertex_cells(v)) {
      if (std::find(nbrs.begin(), nbrs.begin() + count, n) != nbrs.begin() + count) continue;
      if (count == 27 || !m.CellIsHexahedron(n)) return false;
      nbrs[count++] = n;
    }
  }
  return count == 27;
}

// At a regular vertex x (6 edges, 8 hexahedra), the edge that shares no face
// with edge e0.
int32_t OppositeEdge(const CellComplex& m, int32_t x, int32_t e0) {
  const auto& ev0 = m.edge_vertices(e0);
  for (int32_t e : m.vertex_edges(x)) {
    if (e == e0) continue;
    bool shares = false;
    for (int32_t f : m.edge_faces(e0)) {
      const auto edges = m.face_edges(f);
      if (std::find(edges.begin(), edges.end(), e) != edges.end()) {
        shares = true;
        break;
      }
    }
    if (!shares) return e;
  }
  (void)ev0;
  return -1;
}

// The quad face containing x, a and b (a and b neighbours of x): its
// vertex opposite x.
int32_t QuadOpposite(const CellComplex& m, int32_t x, int32_t a, int32_t b) {
  for (int32_t f : m.vertex_faces(x)) {
    const auto loop = m.face_vertices(f);
    if (loop.size() != 4 || !LoopContains(loop, a) || !LoopContains(loop, b)) continue;
    const size_t i = static_cast<size_t>(std::find(loop.begin(), loop.end(), x) - loop.begin());
    return loop[(i + 2) % 4];
  }
  return -1;
}

// The hexahedron around x containing a, b and d: its vertex opposite x
// (the one on no face through x).
int32_t HexOpposite(const CellComplex& m, int32_t x, int32_t a, int32_t b, int32_t d) {
  for (int32_t c : m.vertex_cells(x)) {
    const auto verts = m.cell_vertices(c);
    if (!std::binary_search(verts.begin(), verts.end(), a) ||
        !std::binary_search(verts.begin(), verts.end(), b) ||
        !std::binary_search(verts.begin(), verts.end(), d)) {
      continue;
    }
    for (int32_t v : verts) {
      bool on_face_through_x = false;
      for (int32_t f : m.cell_faces(c)) {
        const auto loop = m.face_vertices(f);
        if (LoopContains(loop, x) && LoopContains(loop, v)) {
          on_face_through_x = true;
          break;
        }
      }
      if (!on_face_through_x) return v;
    }
  }
  return -1;
}

// 64 nodes of a regular hexahedron in tensor order m = 16 i + 4 j + k.
std::array<int32_t, 64> CubicNodes(const CellComplex& m, const std::array<int32_t, 8>& h) {
  std::array<int32_t, 64> nodes;
  nodes.fill(-1);
  auto at = [&](int i, int j, int k) -> int32_t& { return nodes[16 * i + 4 * j + k]; };
  for (int n = 0; n < 8; ++n) {
    const int u = kHexCorner[n][0], v = kHexCorner[n][1], w = kHexCorner[n][2];
    const int32_t x = h[n];
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
      const int32_t e_in = m.FindEdge(x, inside);
      out[axis] = OtherEnd(m, OppositeEdge(m, x, e_in), x);
    }
    const int I = 1 + u, J = 1 + v, K = 1 + w;
    const int Io = u ? 3 : 0, Jo = v ? 3 : 0, Ko = w ? 3 : 0;
    at(I, J, K) = x;
    at(Io, J, K) = out[0];
    at(I, Jo, K) = out[1];
    at(I, J, Ko) = out[2];
    at(Io, Jo, K) = QuadOpposite(m, x, out[0], out[1]);
    at(Io, J, Ko) = QuadOpposite(m, x, out[0], out[2]);
    at(I, Jo, Ko) = QuadOpposite(m, x, out[1], out[2]);
    at(Io, Jo, Ko) = HexOpposite(m, x, out[0], out[1], out[2]);
  }
  return nodes;
}

}  // namespace

ElementSet ClassifyElements(const CellComplex& m) {
  ElementSet s;
  s.num_mesh_vertices = m.num_vertices();
  std::vector<int32_t> loop;
  for (int32_t c = 0; c < m.num_cells(); ++c) {
    if (m.CellIsHexahedron(c)) {
      const std::array<int32_t, 8> h = HexCorners(m, c);
      if (IsRegularHex(m, c)) {
        const std::array<int32_t, 64> nodes = CubicNodes(m, h);
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
    const int32_t apex = s.num_mesh_vertices + s.num_virtual_nodes++;
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
  return s;
}

subdivision::SparseMatrix NodeMatrix(const CellComplex& m, const subdivision::SparseMatrix& a,
                                     const ElementSet& elements) {
  if (elements.num_virtual_nodes == 0) return a;
  using Triplet = Eigen::Triplet<double, int32_t>;
  std::vector<Triplet> t;
  t.reserve(static_cast<size_t>(a.nonZeros()) + elements.virtual_node_cell.size() * 64);
  for (int32_t r = 0; r < a.rows(); ++r) {
    for (subdivision::SparseMatrix::InnerIterator it(a, r); it; ++it) {
      t.emplace_back(r, static_cast<int32_t>(it.col()), it.value());
    }
  }
  for (int32_t i = 0; i < elements.num_virtual_nodes; ++i) {
    const auto verts = m.cell_vertices(elements.virtual_node_cell[i]);
    const double w = 1.0 / static_cast<double>(verts.size());
    for (int32_t v : verts) {
      for (subdivision::SparseMatrix::InnerIterator it(a, v); it; ++it) {
        t.emplace_back(elements.num_mesh_vertices + i, static_cast<int32_t>(it.col()),
                       w * it.value());
      }
    }
  }
  subdivision::SparseMatrix out(elements.num_nodes(), a.cols());
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

}  // namespace dynsolid::fem
