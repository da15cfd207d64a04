#include "solver/models/measure.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <Eigen/Geometry>

#include "solver/models/measure_corner.h"

namespace dynsolid::models {

namespace {

// The edges and corners of the whole mesh, gathered once at construction
// and handed out to the parts.
struct Edge {
  int32_t i, j;
  double rest_length;
};
struct Corner {
  int32_t n, a, b;
  double cos0, sin0;  // of the rest angle
};
struct Quad {
  int32_t face;  // its mesh face (side k is mesh edge face_edges(face)[k])
  std::array<int32_t, 4> v;
  std::array<double, 4> cos0, sin0;  // of corner k's rest angle (at v[k])
  // Side k (v[k] to v[k+1]) carries its edge's stretch term when bit k of
  // `edges` is set, with rest length l0[k] (0 otherwise).
  std::array<double, 4> l0{};
  uint8_t edges = 0;
};

using measure_detail::kQuadRestRow;
using measure_detail::QuadKernels;

// The kernels of a quadrilateral path, null where this build or CPU has
// none. __builtin_cpu_supports also asks whether the OS saves the AVX-512
// registers.
QuadKernels KernelsOf(QuadPath path) {
  switch (path) {
    case QuadPath::kPerCorner:
      return {};
    case QuadPath::kAvx2:
      if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return {};
      return measure_detail::avx2::Kernels();
    case QuadPath::kAvx512:
#ifdef DYNSOLID_MEASURE_AVX512
      if (!__builtin_cpu_supports("avx512f") || !__builtin_cpu_supports("avx512dq") ||
          !__builtin_cpu_supports("avx512vl")) {
        return {};
      }
      return measure_detail::avx512::Kernels();
#else
      return {};
#endif
  }
  return {};
}

void AddEdge(int32_t i, int32_t j, const Points& rest, std::vector<Edge>& edges) {
  edges.push_back({i, j, (rest.row(j) - rest.row(i)).norm()});
}

void AddCorner(int32_t n, int32_t a, int32_t b, const Points& rest,
               std::vector<Corner>& corners) {
  const Eigen::Vector3d ra = rest.row(a) - rest.row(n);
  const Eigen::Vector3d rb = rest.row(b) - rest.row(n);
  const double la = ra.norm(), lb = rb.norm();
  if (la <= 0 || lb <= 0) return;
  corners.push_back({n, a, b, ra.dot(rb) / (la * lb), ra.cross(rb).norm() / (la * lb)});
}

// The edges, corners and quadrilaterals of the whole mesh (before they are
// handed out to the parts).
struct Terms {
  std::vector<Edge> edges;
  std::vector<Corner> corners;
  std::vector<Quad> quads;
};

// The mesh's edges (all of them first, in mesh order) and its faces'
// corners; with a quadrilateral path, whole quadrilaterals in place of
// their corners.
void AddMeshTerms(const mesh::CellComplex& mesh, const Points& rest, QuadPath quad_path,
                  Terms& terms) {
  std::vector<Edge>& edges = terms.edges;
  std::vector<Corner>& corners = terms.corners;
  edges.reserve(mesh.num_edges());
  for (int32_t e = 0; e < mesh.num_edges(); ++e) {
    const auto& ev = mesh.edge_vertices(e);
    AddEdge(ev[0], ev[1], rest, edges);
  }
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const auto loop = mesh.face_vertices(f);
    const size_t k = loop.size();
    const size_t first = corners.size();
    for (size_t i = 0; i < k; ++i) {
      AddCorner(loop[i], loop[(i + k - 1) % k], loop[(i + 1) % k], rest, corners);
    }
    // A quadrilateral with four distinct nodes and four proper rest corners
    // runs as one: its corners leave the per-corner list.
    if (quad_path == QuadPath::kPerCorner || k != 4 || corners.size() != first + 4) continue;
    Quad q;
    q.face = f;
    for (int i = 0; i < 4; ++i) {
      q.v[i] = loop[i];
      q.cos0[i] = corners[first + i].cos0;
      q.sin0[i] = corners[first + i].sin0;
    }
    if (q.v[0] == q.v[2] || q.v[1] == q.v[3]) continue;  // (adjacent ones give zero sides)
    terms.quads.push_back(q);
    corners.resize(first);
  }
}

// Pyramid elements: centre-to-vertex edges and the side triangles, once each.
void AddPyramidTerms(const mesh::CellComplex& mesh, const fem::ElementSet& elements,
                     const Points& rest, Terms& terms) {
  for (int32_t v = 0; v < elements.num_virtual_nodes; ++v) {
    const int32_t apex = elements.num_mesh_vertices + v;
    for (int32_t x : mesh.cell_vertices(elements.virtual_node_cell[v])) {
      AddEdge(apex, x, rest, terms.edges);
    }
  }
  std::set<std::array<int32_t, 3>> triangles;
  for (int32_t p = 0; p < elements.num_pyramid(); ++p) {
    const int32_t* q = &elements.pyramid_nodes[5 * p];
    for (int s = 0; s < 4; ++s) {
      const int32_t a = q[s], b = q[(s + 1) % 4];
      if (a == b) continue;  // degenerate base side (a triangle face)
      std::array<int32_t, 3> key{std::min(a, b), std::max(a, b), q[4]};
      if (!triangles.insert(key).second) continue;
      AddCorner(q[4], a, b, rest, terms.corners);
      AddCorner(a, b, q[4], rest, terms.corners);
      AddCorner(b, q[4], a, rest, terms.corners);
    }
  }
}

// Every edge that is a side of a quadrilateral runs with the first such
// quadrilateral (its stretch term computed from the side's length and
// inverse, which the corners need anyway) and leaves the edge list. The
// first mesh.num_edges() entries of `edges` are the mesh's edges in
// order, so side k of a quadrilateral is edges[face_edges(face)[k]].
// Returns, per entry of terms.edges, whether it now runs with a
// quadrilateral.
std::vector<uint8_t> FuseQuadSides(const mesh::CellComplex& mesh, Terms& terms) {
  const std::vector<Edge>& edges = terms.edges;
  std::vector<uint8_t> fused(edges.size(), 0);
  for (Quad& q : terms.quads) {
    const auto side_edges = mesh.face_edges(q.face);
    for (int k = 0; k < 4; ++k) {
      const int32_t e = side_edges[k];
      if (fused[e]) continue;
      fused[e] = 1;
      q.edges |= static_cast<uint8_t>(1 << k);
      // The side runs v[k] -> v[k+1]; the edge's term is the same either way.
      q.l0[k] = edges[e].rest_length;
    }
  }
  return fused;
}

// Ownership: cells in `parts` contiguous ranges; a node goes to the part
// of its lowest-numbered cell. Returns each of the `nodes` nodes' part.
std::vector<uint8_t> NodeOwners(const mesh::CellComplex& mesh, const fem::ElementSet& elements,
                                int32_t nodes, int parts) {
  const int64_t cells = std::max(1, mesh.num_cells());
  auto part_of_cell = [&](int32_t c) { return static_cast<uint8_t>(c * parts / cells); };
  std::vector<uint8_t> owner(nodes, 0);
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    int32_t lowest = cells;
    for (int32_t c : mesh.vertex_cells(v)) lowest = std::min(lowest, c);
    owner[v] = lowest < cells ? part_of_cell(lowest) : 0;
  }
  for (int32_t v = 0; v < elements.num_virtual_nodes; ++v) {
    owner[elements.num_mesh_vertices + v] = part_of_cell(elements.virtual_node_cell[v]);
  }
  return owner;
}

// Whether ks[t] differs from ks[0 .. t): each edge and corner is listed
// once for every distinct part owning one of its nodes.
bool DistinctPart(const int* ks, int t) {
  for (int u = 0; u < t; ++u) {
    if (ks[u] == ks[t]) return false;
  }
  return true;
}

// Rest lengths and quadrilateral rest corners, each distinct value (to
// the bit) once: a regular block has one of each, so a term carries a
// 4-byte index instead of 8 (edges) or 64 bytes (quadrilaterals), and
// the passes stream that much less. Appends new values to the tables
// it is given and returns their rows.
class RestTables {
 public:
  RestTables(std::vector<double>& edge_rest, std::vector<double>& quad_rest)
      : edge_rest_(edge_rest), quad_rest_(quad_rest) {}

  uint32_t EdgeId(double length) {
    auto [it, added] = edge_index_.try_emplace(length, static_cast<uint32_t>(edge_rest_.size()));
    if (added) edge_rest_.push_back(length);
    return it->second;
  }

  uint32_t QuadId(const Quad& q) {
    std::array<double, kQuadRestRow> key;
    std::copy(q.cos0.begin(), q.cos0.end(), key.begin());
    std::copy(q.sin0.begin(), q.sin0.end(), key.begin() + 4);
    std::copy(q.l0.begin(), q.l0.end(), key.begin() + 8);
    auto [it, added] =
        quad_index_.try_emplace(key, static_cast<uint32_t>(quad_rest_.size() / kQuadRestRow));
    if (added) quad_rest_.insert(quad_rest_.end(), key.begin(), key.end());
    return it->second;
  }

 private:
  std::vector<double>& edge_rest_;
  std::vector<double>& quad_rest_;
  std::map<double, uint32_t> edge_index_;
  std::map<std::array<double, kQuadRestRow>, uint32_t> quad_index_;
};

}  // namespace

bool QuadPathRuns(QuadPath path) {
  return path == QuadPath::kPerCorner || KernelsOf(path).forward != nullptr;
}

QuadPath FastestQuadPath() {
  static const QuadPath fastest = [] {
    for (QuadPath p : {QuadPath::kAvx512, QuadPath::kAvx2}) {
      if (QuadPathRuns(p)) return p;
    }
    return QuadPath::kPerCorner;
  }();
  return fastest;
}

const char* QuadPathName(QuadPath path) {
  switch (path) {
    case QuadPath::kPerCorner:
      return "per-corner";
    case QuadPath::kAvx2:
      return "avx2";
    case QuadPath::kAvx512:
      return "avx512";
  }
  return "?";
}

DeformationMeasure::DeformationMeasure(const mesh::CellComplex& mesh,
                                       const fem::ElementSet& elements, const Points& rest,
                                       int parts, QuadPath quads) {
  quad_path_ = QuadPathRuns(quads) ? quads : FastestQuadPath();
  quads_ = KernelsOf(quad_path_);
  Terms terms;
  AddMeshTerms(mesh, rest, quad_path_, terms);
  AddPyramidTerms(mesh, elements, rest, terms);
  const std::vector<uint8_t> fused = FuseQuadSides(mesh, terms);
  const std::vector<Edge>& edges = terms.edges;
  const std::vector<Corner>& corners = terms.corners;
  const std::vector<Quad>& quad_list = terms.quads;

  parts = std::clamp(parts, 1, 255);
  const int32_t nodes = static_cast<int32_t>(rest.rows());
  owner_ = NodeOwners(mesh, elements, nodes, parts);
  parts_.assign(parts, Part{});
  for (int32_t v = 0; v < nodes; ++v) parts_[owner_[v]].nodes.push_back(v);
  // Each edge and corner is listed once for every distinct part owning one
  // of its nodes (DistinctPart), with its rest values' rows (RestTables).
  RestTables rest_tables(edge_rest_, quad_rest_);
  for (size_t e = 0; e < edges.size(); ++e) {
    if (fused[e]) continue;
    const Edge& edge = edges[e];
    const int ks[2] = {owner_[edge.i], owner_[edge.j]};
    for (int t = 0; t < 2; ++t) {
      if (!DistinctPart(ks, t)) continue;
      Part& p = parts_[ks[t]];
      p.ei.push_back(edge.i);
      p.ej.push_back(edge.j);
      p.e_rest.push_back(rest_tables.EdgeId(edge.rest_length));
      p.e_owns.push_back((ks[0] == ks[t] ? 1 : 0) | (ks[1] == ks[t] ? 2 : 0));
    }
  }
  for (const Quad& q : quad_list) {
    const int ks[4] = {owner_[q.v[0]], owner_[q.v[1]], owner_[q.v[2]], owner_[q.v[3]]};
    for (int t = 0; t < 4; ++t) {
      if (!DistinctPart(ks, t)) continue;
      Part& p = parts_[ks[t]];
      uint8_t owns = 0;
      for (int i = 0; i < 4; ++i) {
        p.qv.push_back(q.v[i]);
        if (ks[i] == ks[t]) owns |= static_cast<uint8_t>(1 << i);
      }
      p.q_rest.push_back(rest_tables.QuadId(q));
      p.q_owns.push_back(static_cast<uint8_t>(owns | (q.edges << 4)));
    }
  }
  for (const Corner& c : corners) {
    const int ks[3] = {owner_[c.a], owner_[c.b], owner_[c.n]};
    for (int t = 0; t < 3; ++t) {
      if (!DistinctPart(ks, t)) continue;
      Part& p = parts_[ks[t]];
      p.cn.push_back(c.n);
      p.ca.push_back(c.a);
      p.cb.push_back(c.b);
      p.cos0.push_back(c.cos0);
      p.sin0.push_back(c.sin0);
      p.c_owns.push_back((ks[0] == ks[t] ? 1 : 0) | (ks[1] == ks[t] ? 2 : 0) |
                         (ks[2] == ks[t] ? 4 : 0));
    }
  }
  // The parts hold everything a pass needs; the global lists only counted.
  num_edges_ = static_cast<int64_t>(edges.size());
  num_quads_ = static_cast<int64_t>(quad_list.size());
  num_corners_ = static_cast<int64_t>(corners.size()) + 4 * num_quads_;
  for (Part& p : parts_) {
    for (auto* v : {&p.nodes, &p.ei, &p.ej, &p.qv, &p.cn, &p.ca, &p.cb}) v->shrink_to_fit();
    for (auto* v : {&p.e_rest, &p.q_rest}) v->shrink_to_fit();
    for (auto* v : {&p.cos0, &p.sin0}) v->shrink_to_fit();
    for (auto* v : {&p.e_owns, &p.q_owns, &p.c_owns}) v->shrink_to_fit();
  }
}

int64_t DeformationMeasure::bytes() const {
  auto b = [](const auto& v) { return static_cast<int64_t>(v.size() * sizeof(v[0])); };
  int64_t n = b(owner_) + b(edge_rest_) + b(quad_rest_);
  for (const Part& p : parts_) {
    n += b(p.nodes) + b(p.ei) + b(p.ej) + b(p.e_rest) + b(p.e_owns) + b(p.qv) + b(p.q_rest) +
         b(p.q_owns) + b(p.cn) + b(p.ca) + b(p.cb) + b(p.cos0) + b(p.sin0) + b(p.c_owns);
  }
  return n;
}

int64_t DeformationMeasure::terms_per_pass() const {
  int64_t n = 0;
  for (const Part& p : parts_) {
    n += static_cast<int64_t>(p.ei.size() + p.cn.size() + 4 * p.q_owns.size());
    for (uint8_t o : p.q_owns) n += __builtin_popcount(o >> 4);  // sides' edge terms
  }
  return n;
}

namespace {

using measure_detail::CornerGeometry;
using measure_detail::CornerTerms;
using measure_detail::ForwardTerms;
using measure_detail::MeasureCorner;
using measure_detail::MeasureSide;
using measure_detail::TransposeTerms;

// The geometry loops below take their arrays as restrict-qualified
// parameters, which is what lets GCC run them in SIMD lanes (gathers of
// the node rows, square roots, divisions and selects four at a time).
// They run over chunks of kChunk terms whose results stay in L1 until the
// scalar adds take them; no per-term state outlives a chunk, and the
// transpose recomputes the geometry from d (a few dozen operations per
// term, cheaper than writing and reading back 20 doubles per corner).
#define R __restrict

constexpr int64_t kChunk = 256;

// Edge (i, j): r = d_j - d_i, l = |r| and the stretch term f r with
// f = (l - l0) / (2 l) (zero for a zero-length edge).
void EdgeForward(const double* R pd, const int32_t* R ei, const int32_t* R ej,
                 const double* R rest, const uint32_t* R rest_id, double* R fx, double* R fy,
                 double* R fz, int64_t ne) {
  for (int64_t q = 0; q < ne; ++q) {
    const int64_t i = 3 * static_cast<int64_t>(ei[q]), j = 3 * static_cast<int64_t>(ej[q]);
    const double x = pd[j] - pd[i], y = pd[j + 1] - pd[i + 1], z = pd[j + 2] - pd[i + 2];
    const double len = std::sqrt(x * x + y * y + z * z);
    const double f_any = 0.5 * (len - rest[rest_id[q]]) / (len > 0 ? len : 1.0);
    const double f = len > 0 ? f_any : 0.0;
    fx[q] = f * x;
    fy[q] = f * y;
    fz[q] = f * z;
  }
}
// The corner terms on a and b (n's is minus their sum).
void CornerForward(const double* R pd, const int32_t* R cn, const int32_t* R ca,
                   const int32_t* R cb, const double* R cos0, const double* R sin0,
                   double* R tax, double* R tay, double* R taz, double* R tbx, double* R tby,
                   double* R tbz, int64_t nc) {
  for (int64_t q = 0; q < nc; ++q) {
    const int64_t n = 3 * static_cast<int64_t>(cn[q]);
    const int64_t a = 3 * static_cast<int64_t>(ca[q]), b = 3 * static_cast<int64_t>(cb[q]);
    const double rax = pd[a] - pd[n], ray = pd[a + 1] - pd[n + 1], raz = pd[a + 2] - pd[n + 2];
    const double rbx = pd[b] - pd[n], rby = pd[b + 1] - pd[n + 1], rbz = pd[b + 2] - pd[n + 2];
    const CornerGeometry<double> g =
        MeasureCorner<double>(rax, ray, raz, rbx, rby, rbz, MeasureSide(rax, ray, raz),
                              MeasureSide(rbx, rby, rbz), cos0[q], sin0[q]);
    const CornerTerms<double> t = ForwardTerms(rax, ray, raz, rbx, rby, rbz, g);
    tax[q] = t.ax, tay[q] = t.ay, taz[q] = t.az;
    tbx[q] = t.bx, tby[q] = t.by, tbz[q] = t.bz;
  }
}

// Edge (i, j): c = 1/2 (1 - l0 / l) r with r = d_j - d_i adds to delta_j and
// subtracts from delta_i, so d/dr of (y_j - y_i) . c is
// J (y_j - y_i) with J = 1/2 [(1 - l0/l) I + (l0 / l^3) r r^T].
void EdgeTranspose(const double* R pd, const double* R py, const int32_t* R ei,
                   const int32_t* R ej, const double* R rest, const uint32_t* R rest_id,
                   double* R fx, double* R fy, double* R fz, int64_t ne) {
  for (int64_t q = 0; q < ne; ++q) {
    const double l0 = rest[rest_id[q]];
    const int64_t i = 3 * static_cast<int64_t>(ei[q]), j = 3 * static_cast<int64_t>(ej[q]);
    const double rx = pd[j] - pd[i], ry = pd[j + 1] - pd[i + 1], rz = pd[j + 2] - pd[i + 2];
    const double len = std::sqrt(rx * rx + ry * ry + rz * rz);
    const double dx = py[j] - py[i], dy = py[j + 1] - py[i + 1], dz = py[j + 2] - py[i + 2];
    const bool ok = len > 0;
    const double il = 1.0 / (ok ? len : 1.0);
    const double rdy = rx * dx + ry * dy + rz * dz;
    const double c1_any = 0.5 * (1.0 - l0 * il);
    const double c2_any = 0.5 * l0 * il * il * il * rdy;
    const double c1 = ok ? c1_any : 0.0, c2 = ok ? c2_any : 0.0;
    fx[q] = c1 * dx + c2 * rx;
    fy[q] = c1 * dy + c2 * ry;
    fz[q] = c1 * dz + c2 * rz;
  }
}

// Corner (n; a, b): with ra = a - n, rb = b - n, c = cos(theta),
// s = sin(theta), phi = (theta - theta0)/2, C = cos(phi), S = sin(phi), the
// rotations give delta_a = alpha ra - beta la b^, delta_b = alpha rb - beta lb a^
// with alpha = 1 - C + c S / s and beta = S / s. For F = ya.delta_a + yb.delta_b
// = alpha P - beta Q (P = ya.ra + yb.rb, Q = la ya.b^ + lb yb.a^) and
// dtheta/dra = -ta / la, dtheta/drb = -tb / lb (ta, tb the in-plane unit
// vectors perpendicular to a^ and b^ towards each other, s ta = b^ - c a^):
//   dF/dra = (P alpha' - Q beta') (-ta / la) + alpha ya
//            - beta [(ya.b^) a^ + (lb / la)(yb - (yb.a^) a^)],
// and symmetrically for rb; n gets minus both.
void CornerTranspose(const double* R pd, const double* R py, const int32_t* R cn,
                     const int32_t* R ca, const int32_t* R cb, const double* R cos0,
                     const double* R sin0, double* R tax, double* R tay, double* R taz,
                     double* R tbx, double* R tby, double* R tbz, int64_t nc) {
  for (int64_t q = 0; q < nc; ++q) {
    const int64_t n = 3 * static_cast<int64_t>(cn[q]);
    const int64_t a = 3 * static_cast<int64_t>(ca[q]), b = 3 * static_cast<int64_t>(cb[q]);
    const double rax = pd[a] - pd[n], ray = pd[a + 1] - pd[n + 1], raz = pd[a + 2] - pd[n + 2];
    const double rbx = pd[b] - pd[n], rby = pd[b + 1] - pd[n + 1], rbz = pd[b + 2] - pd[n + 2];
    const CornerGeometry<double> g =
        MeasureCorner<double>(rax, ray, raz, rbx, rby, rbz, MeasureSide(rax, ray, raz),
                              MeasureSide(rbx, rby, rbz), cos0[q], sin0[q]);
    const double yax = py[a], yay = py[a + 1], yaz = py[a + 2];
    const double ybx = py[b], yby = py[b + 1], ybz = py[b + 2];
    const CornerTerms<double> t = TransposeTerms(yax, yay, yaz, ybx, yby, ybz, g);
    tax[q] = t.ax, tay[q] = t.ay, taz[q] = t.az;
    tbx[q] = t.bx, tby[q] = t.by, tbz[q] = t.bz;
  }
}

#undef R

// One chunk's terms, kept in L1 between the geometry loop and the adds.
struct ChunkTerms {
  alignas(64) double x0[kChunk], y0[kChunk], z0[kChunk];  // edges: f; corners: ta
  alignas(64) double x1[kChunk], y1[kChunk], z1[kChunk];  // corners: tb
};

inline void AddRow(double* out, int32_t v, double x, double y, double z) {
  double* o = out + 3 * static_cast<int64_t>(v);
  o[0] += x;
  o[1] += y;
  o[2] += z;
}


}  // namespace

template <typename EdgeTerms, typename QuadTerms, typename CornerTerms>
void DeformationMeasure::RunPart(const Part& p, bool centres, double* out,
                                 std::initializer_list<const double*> inputs,
                                 EdgeTerms edge_terms, QuadTerms quad_terms,
                                 CornerTerms corner_terms) {
  for (int32_t v : p.nodes) out[3 * v] = out[3 * v + 1] = out[3 * v + 2] = 0;
  // While a chunk's terms are added, the next chunk's node rows (of the
  // inputs and the output) are prefetched, one term per term added.
  auto prefetch = [&](int32_t v) {
    const int64_t row = 3 * static_cast<int64_t>(v);
    for (const double* base : inputs) __builtin_prefetch(base + row);
    __builtin_prefetch(out + row, 1);
  };
  ChunkTerms t;
  const int64_t ne = static_cast<int64_t>(p.ei.size());
  for (int64_t q0 = 0; q0 < ne; q0 += kChunk) {
    const int64_t m = std::min(kChunk, ne - q0);
    edge_terms(q0, m, t.x0, t.y0, t.z0);
    const int64_t ahead = std::min(kChunk, std::max<int64_t>(ne - q0 - kChunk, 0));
    for (int64_t u = 0; u < m; ++u) {
      if (u < ahead) {
        prefetch(p.ei[q0 + kChunk + u]);
        prefetch(p.ej[q0 + kChunk + u]);
      }
      const uint8_t owns = p.e_owns[q0 + u];
      if (owns & 1) AddRow(out, p.ei[q0 + u], -t.x0[u], -t.y0[u], -t.z0[u]);
      if (owns & 2) AddRow(out, p.ej[q0 + u], t.x0[u], t.y0[u], t.z0[u]);
    }
  }
  quad_terms(out);
  const int64_t nc = static_cast<int64_t>(p.cn.size());
  for (int64_t q0 = 0; q0 < nc; q0 += kChunk) {
    const int64_t m = std::min(kChunk, nc - q0);
    corner_terms(q0, m, t.x0, t.y0, t.z0, t.x1, t.y1, t.z1);
    const int64_t ahead = std::min(kChunk, std::max<int64_t>(nc - q0 - kChunk, 0));
    for (int64_t u = 0; u < m; ++u) {
      if (u < ahead) {
        prefetch(p.cn[q0 + kChunk + u]);
        prefetch(p.ca[q0 + kChunk + u]);
        prefetch(p.cb[q0 + kChunk + u]);
      }
      const uint8_t owns = p.c_owns[q0 + u];
      if (owns & 1) AddRow(out, p.ca[q0 + u], t.x0[u], t.y0[u], t.z0[u]);
      if (owns & 2) AddRow(out, p.cb[q0 + u], t.x1[u], t.y1[u], t.z1[u]);
      if (centres && (owns & 4)) {
        AddRow(out, p.cn[q0 + u], -(t.x0[u] + t.x1[u]), -(t.y0[u] + t.y1[u]),
               -(t.z0[u] + t.z1[u]));
      }
    }
  }
}

void DeformationMeasure::ForwardPart(const Points& d, int k, Points& delta) const {
  const Part& p = parts_[k];
  const double* pd = d.data();
  RunPart(
      p, /*centres=*/false, delta.data(), {pd},
      [&](int64_t q0, int64_t m, double* fx, double* fy, double* fz) {
        EdgeForward(pd, p.ei.data() + q0, p.ej.data() + q0, edge_rest_.data(),
                    p.e_rest.data() + q0, fx, fy, fz, m);
      },
      [&](double* out) {
        if (p.q_owns.empty()) return;
        quads_.forward(p.qv.data(), quad_rest_.data(), p.q_rest.data(), p.q_owns.data(),
                     static_cast<int64_t>(p.q_owns.size()), pd, out);
      },
      [&](int64_t q0, int64_t m, double* ax, double* ay, double* az, double* bx, double* by,
          double* bz) {
        CornerForward(pd, p.cn.data() + q0, p.ca.data() + q0, p.cb.data() + q0,
                      p.cos0.data() + q0, p.sin0.data() + q0, ax, ay, az, bx, by, bz, m);
      });
}

void DeformationMeasure::TransposePart(const Points& d, const Points& y, int k,
                                       Points& out) const {
  const Part& p = parts_[k];
  const double* pd = d.data();
  const double* py = y.data();
  RunPart(
      p, /*centres=*/true, out.data(), {pd, py},
      [&](int64_t q0, int64_t m, double* fx, double* fy, double* fz) {
        EdgeTranspose(pd, py, p.ei.data() + q0, p.ej.data() + q0, edge_rest_.data(),
                      p.e_rest.data() + q0, fx, fy, fz, m);
      },
      [&](double* out) {
        if (p.q_owns.empty()) return;
        quads_.transpose(p.qv.data(), quad_rest_.data(), p.q_rest.data(), p.q_owns.data(),
                       static_cast<int64_t>(p.q_owns.size()), pd, py, out);
      },
      [&](int64_t q0, int64_t m, double* ax, double* ay, double* az, double* bx, double* by,
          double* bz) {
        CornerTranspose(pd, py, p.cn.data() + q0, p.ca.data() + q0, p.cb.data() + q0,
                        p.cos0.data() + q0, p.sin0.data() + q0, ax, ay, az, bx, by, bz, m);
      });
}

void DeformationMeasure::Apply(const Points& d, Points& delta) const {
  delta.resize(d.rows(), 3);
  for (int k = 0; k < parts(); ++k) ForwardPart(d, k, delta);
}

void DeformationMeasure::ApplyTranspose(const Points& d, const Points& y, Points& out) const {
  out.resize(y.rows(), 3);
  for (int k = 0; k < parts(); ++k) TransposePart(d, y, k, out);
}

}  // namespace dynsolid::models
