#include "solver/models/measure.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <Eigen/Geometry>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>

#include "solver/models/simd_rows.h"
#define DYNSOLID_MEASURE_AVX2 1
#endif

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

// A quadrilateral's row of the measure's rest table: cos0[4], sin0[4], l0[4].
constexpr int kQuadRestRow = 12;

#ifdef DYNSOLID_MEASURE_AVX2
constexpr bool kQuadLanes = true;
#else
constexpr bool kQuadLanes = false;
#endif

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

}  // namespace

DeformationMeasure::DeformationMeasure(const mesh::CellComplex& mesh,
                                       const fem::ElementSet& elements, const Points& rest,
                                       int parts, bool quads) {
  std::vector<Edge> edges;
  std::vector<Corner> corners;
  std::vector<Quad> quad_list;
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
    if (!quads || !kQuadLanes || k != 4 || corners.size() != first + 4) continue;
    Quad q;
    q.face = f;
    for (int i = 0; i < 4; ++i) {
      q.v[i] = loop[i];
      q.cos0[i] = corners[first + i].cos0;
      q.sin0[i] = corners[first + i].sin0;
    }
    if (q.v[0] == q.v[2] || q.v[1] == q.v[3]) continue;  // (adjacent ones give zero sides)
    quad_list.push_back(q);
    corners.resize(first);
  }
  // Pyramid elements: centre-to-vertex edges and the side triangles, once each.
  for (int32_t v = 0; v < elements.num_virtual_nodes; ++v) {
    const int32_t apex = elements.num_mesh_vertices + v;
    for (int32_t x : mesh.cell_vertices(elements.virtual_node_cell[v])) AddEdge(apex, x, rest, edges);
  }
  std::set<std::array<int32_t, 3>> triangles;
  for (int32_t p = 0; p < elements.num_pyramid(); ++p) {
    const int32_t* q = &elements.pyramid_nodes[5 * p];
    for (int s = 0; s < 4; ++s) {
      const int32_t a = q[s], b = q[(s + 1) % 4];
      if (a == b) continue;  // degenerate base side (a triangle face)
      std::array<int32_t, 3> key{std::min(a, b), std::max(a, b), q[4]};
      if (!triangles.insert(key).second) continue;
      AddCorner(q[4], a, b, rest, corners);
      AddCorner(a, b, q[4], rest, corners);
      AddCorner(b, q[4], a, rest, corners);
    }
  }

  // Every edge that is a side of a quadrilateral runs with the first such
  // quadrilateral (its stretch term computed from the side's length and
  // inverse, which the corners need anyway) and leaves the edge list. The
  // first mesh.num_edges() entries of `edges` are the mesh's edges in
  // order, so side k of a quadrilateral is edges[face_edges(face)[k]].
  std::vector<uint8_t> fused(edges.size(), 0);
  for (Quad& q : quad_list) {
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

  // Ownership: cells in `parts` contiguous ranges; a node goes to the part
  // of its lowest-numbered cell.
  parts = std::clamp(parts, 1, 255);
  const int32_t nodes = static_cast<int32_t>(rest.rows());
  const int64_t cells = std::max(1, mesh.num_cells());
  auto part_of_cell = [&](int32_t c) { return static_cast<uint8_t>(c * parts / cells); };
  owner_.assign(nodes, 0);
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    int32_t lowest = cells;
    for (int32_t c : mesh.vertex_cells(v)) lowest = std::min(lowest, c);
    owner_[v] = lowest < cells ? part_of_cell(lowest) : 0;
  }
  for (int32_t v = 0; v < elements.num_virtual_nodes; ++v) {
    owner_[elements.num_mesh_vertices + v] = part_of_cell(elements.virtual_node_cell[v]);
  }
  parts_.assign(parts, Part{});
  for (int32_t v = 0; v < nodes; ++v) parts_[owner_[v]].nodes.push_back(v);
  // Each edge and corner is listed once for every distinct part owning one
  // of its nodes.
  auto distinct = [](const int* ks, int t) {
    for (int u = 0; u < t; ++u) {
      if (ks[u] == ks[t]) return false;
    }
    return true;
  };
  // Rest lengths and quadrilateral rest corners, each distinct value (to
  // the bit) once: a regular block has one of each, so a term carries a
  // 4-byte index instead of 8 (edges) or 64 bytes (quadrilaterals), and
  // the passes stream that much less.
  std::map<double, uint32_t> edge_index;
  auto edge_rest_id = [&](double length) {
    auto [it, added] = edge_index.try_emplace(length, static_cast<uint32_t>(edge_rest_.size()));
    if (added) edge_rest_.push_back(length);
    return it->second;
  };
  std::map<std::array<double, kQuadRestRow>, uint32_t> quad_index;
  auto quad_rest_id = [&](const Quad& q) {
    std::array<double, kQuadRestRow> key;
    std::copy(q.cos0.begin(), q.cos0.end(), key.begin());
    std::copy(q.sin0.begin(), q.sin0.end(), key.begin() + 4);
    std::copy(q.l0.begin(), q.l0.end(), key.begin() + 8);
    auto [it, added] =
        quad_index.try_emplace(key, static_cast<uint32_t>(quad_rest_.size() / kQuadRestRow));
    if (added) quad_rest_.insert(quad_rest_.end(), key.begin(), key.end());
    return it->second;
  };
  for (size_t e = 0; e < edges.size(); ++e) {
    if (fused[e]) continue;
    const Edge& edge = edges[e];
    const int ks[2] = {owner_[edge.i], owner_[edge.j]};
    for (int t = 0; t < 2; ++t) {
      if (!distinct(ks, t)) continue;
      Part& p = parts_[ks[t]];
      p.ei.push_back(edge.i);
      p.ej.push_back(edge.j);
      p.e_rest.push_back(edge_rest_id(edge.rest_length));
      p.e_owns.push_back((ks[0] == ks[t] ? 1 : 0) | (ks[1] == ks[t] ? 2 : 0));
    }
  }
  for (const Quad& q : quad_list) {
    const int ks[4] = {owner_[q.v[0]], owner_[q.v[1]], owner_[q.v[2]], owner_[q.v[3]]};
    for (int t = 0; t < 4; ++t) {
      if (!distinct(ks, t)) continue;
      Part& p = parts_[ks[t]];
      uint8_t owns = 0;
      for (int i = 0; i < 4; ++i) {
        p.qv.push_back(q.v[i]);
        if (ks[i] == ks[t]) owns |= static_cast<uint8_t>(1 << i);
      }
      p.q_rest.push_back(quad_rest_id(q));
      p.q_owns.push_back(static_cast<uint8_t>(owns | (q.edges << 4)));
    }
  }
  for (const Corner& c : corners) {
    const int ks[3] = {owner_[c.a], owner_[c.b], owner_[c.n]};
    for (int t = 0; t < 3; ++t) {
      if (!distinct(ks, t)) continue;
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

// The corner formulas are written once, for a value type T: double (the
// per-corner loops, which GCC runs in SIMD lanes) or Lanes (four corners of
// a quadrilateral in one AVX2 register). Conditions are masks of T: 0 or 1
// for double (bool lanes keep GCC from vectorizing), all bits for Lanes.
inline double Sqrt(double a) { return std::sqrt(a); }
inline double Min(double a, double b) { return std::min(a, b); }
inline double Max(double a, double b) { return std::max(a, b); }
inline double Greater(double a, double b) { return a > b ? 1.0 : 0.0; }
inline double NotLess(double a, double b) { return a >= b ? 1.0 : 0.0; }
inline double And(double m, double n) { return m > 0 ? n : 0.0; }
inline double Select(double m, double a, double b) { return m > 0 ? a : b; }

#ifdef DYNSOLID_MEASURE_AVX2
// Two quadrilaterals' corners (lane k of register h: corner k of
// quadrilateral h): two AVX2 registers, each operation issued on
// both back to back. The corner formulas are a chain of dependent square
// roots and divisions; two independent chains side by side keep the units
// busy where one quadrilateral at a time waits on its own latency.
struct Lanes {
  __m256d v[2];
  Lanes() = default;
  Lanes(__m256d a, __m256d b) : v{a, b} {}
  Lanes(double x) : v{_mm256_set1_pd(x), _mm256_set1_pd(x)} {}  // NOLINT: implicit
};
#define DYNSOLID_LANES_OP(name, expr)                              \
  inline Lanes name(Lanes a, Lanes b) {                            \
    return {[&](__m256d x, __m256d y) { return expr; }(a.v[0], b.v[0]), \
            [&](__m256d x, __m256d y) { return expr; }(a.v[1], b.v[1])}; \
  }
DYNSOLID_LANES_OP(operator+, _mm256_add_pd(x, y))
DYNSOLID_LANES_OP(operator-, _mm256_sub_pd(x, y))
DYNSOLID_LANES_OP(operator*, _mm256_mul_pd(x, y))
DYNSOLID_LANES_OP(operator/, _mm256_div_pd(x, y))
// std::min(a, b) is (b < a ? b : a), std::max(a, b) is (a < b ? b : a):
// vminpd and vmaxpd return their second operand on ties and NaNs.
DYNSOLID_LANES_OP(Min, _mm256_min_pd(y, x))
DYNSOLID_LANES_OP(Max, _mm256_max_pd(y, x))
DYNSOLID_LANES_OP(Greater, _mm256_cmp_pd(x, y, _CMP_GT_OQ))
DYNSOLID_LANES_OP(NotLess, _mm256_cmp_pd(x, y, _CMP_GE_OQ))
DYNSOLID_LANES_OP(And, _mm256_and_pd(x, y))
#undef DYNSOLID_LANES_OP
inline Lanes operator-(Lanes a) {
  const __m256d sign = _mm256_set1_pd(-0.0);
  return {_mm256_xor_pd(a.v[0], sign), _mm256_xor_pd(a.v[1], sign)};
}
inline Lanes Sqrt(Lanes a) { return {_mm256_sqrt_pd(a.v[0]), _mm256_sqrt_pd(a.v[1])}; }
inline Lanes Select(Lanes m, Lanes a, Lanes b) {
  return {_mm256_blendv_pd(b.v[0], a.v[0], m.v[0]), _mm256_blendv_pd(b.v[1], a.v[1], m.v[1])};
}
// Within each quadrilateral, lane k takes lane k + 1 (Next) or lane k - 1
// (Prev), cyclically.
inline Lanes Next(Lanes a) {
  return {_mm256_permute4x64_pd(a.v[0], 0x39), _mm256_permute4x64_pd(a.v[1], 0x39)};
}
inline Lanes Prev(Lanes a) {
  return {_mm256_permute4x64_pd(a.v[0], 0x93), _mm256_permute4x64_pd(a.v[1], 0x93)};
}
#endif

// Corner geometry (n; a, b) from ra = a - n and rb = b - n: with
// phi = (theta - theta0) / 2, C = cos(phi), S = sin(phi), rotating a by
// +phi and b by -phi about n gives delta_a = alpha ra - beta la b^ and
// delta_b = alpha rb - beta lb a^, alpha = 1 - C + c S / s, beta = S / s
// (c, s the cosine and sine of the current angle). A degenerate corner (a
// zero side, collinear sides, or an angle half a turn from its rest value)
// contributes nothing: its alpha, beta and their derivatives in theta are
// zero and its other values finite.
template <typename T>
struct CornerGeometry {
  T ax, ay, az, bx, by, bz;  // unit sides a^, b^
  T la, lb;                  // side lengths (1 for a zero side)
  T ia, ib;                  // their inverses (0 for a zero side)
  T c, inv_s;                // cos theta, 1 / sin theta
  T al, bt, dal, dbt;        // alpha, beta and their theta derivatives
};

// A side's length and inverse: l = |r| and 1 / l (1 for a zero side).
template <typename T>
struct Side {
  T l, inv;
};
template <typename T>
[[gnu::always_inline]] inline Side<T> MeasureSide(T rx, T ry, T rz) {
  const T l = Sqrt(rx * rx + ry * ry + rz * rz);
  return {l, T(1.0) / Select(Greater(l, T(0.0)), l, T(1.0))};
}

// The corner's geometry from its sides ra, rb, their lengths and inverses
// (MeasureSide), and its rest angle's cosine and sine.
template <typename T>
[[gnu::always_inline]] inline CornerGeometry<T> MeasureCorner(T rax, T ray, T raz, T rbx, T rby,
                                                              T rbz, Side<T> sa, Side<T> sb,
                                                              T cos0, T sin0) {
  CornerGeometry<T> g;
  const T lra = sa.l, lrb = sb.l;
  const T sides = Greater(Min(lra, lrb), T(0.0));
  const T ia = Select(sides, sa.inv, T(0.0)), ib = Select(sides, sb.inv, T(0.0));
  g.ax = rax * ia, g.ay = ray * ia, g.az = raz * ia;
  g.bx = rbx * ib, g.by = rby * ib, g.bz = rbz * ib;
  const T c = g.ax * g.bx + g.ay * g.by + g.az * g.bz;
  const T x0 = g.ay * g.bz - g.az * g.by, x1 = g.az * g.bx - g.ax * g.bz,
          x2 = g.ax * g.by - g.ay * g.bx;
  const T sn = Sqrt(x0 * x0 + x1 * x1 + x2 * x2);
  // phi in (-pi/2, pi/2) by half-angle formulas.
  const T cos_d = c * cos0 + sn * sin0;
  const T sin_d = sn * cos0 - c * sin0;
  const T cap_c = Sqrt(Max(T(0.0), T(0.5) * (T(1.0) + cos_d)));
  const T ok_s = And(Greater(sn, T(1e-300)), sides);
  const T okf = And(NotLess(cap_c, T(1e-12)), ok_s);
  const T s_safe = Select(okf, sn, T(1.0)), c_safe = Select(okf, cap_c, T(1.0));
  const T is = T(1.0) / s_safe;
  const T cap_s = sin_d / (T(2.0) * c_safe);
  const T bt_any = cap_s * is;
  const T al_any = T(1.0) - c_safe + c * bt_any;
  const T dal_any = T(-0.5) * cap_s + c * c_safe * T(0.5) * is - c * c * cap_s * is * is;
  const T dbt_any = c_safe * T(0.5) * is - cap_s * c * is * is;
  g.bt = Select(okf, bt_any, T(0.0));
  g.al = Select(okf, al_any, T(0.0));
  g.dal = Select(okf, dal_any, T(0.0));
  g.dbt = Select(okf, dbt_any, T(0.0));
  g.la = Select(sides, lra, T(1.0));
  g.lb = Select(sides, lrb, T(1.0));
  g.ia = ia;
  g.ib = ib;
  g.c = c;
  g.inv_s = is;
  return g;
}

// A corner's terms on a and b.
template <typename T>
struct CornerTerms {
  T ax, ay, az, bx, by, bz;
};

// Forward: delta_a = alpha ra - beta la b^, delta_b = alpha rb - beta lb a^.
template <typename T>
[[gnu::always_inline]] inline CornerTerms<T> ForwardTerms(T rax, T ray, T raz, T rbx, T rby,
                                                          T rbz, const CornerGeometry<T>& g) {
  // With a zero side, la/lb hold 1 but alpha = beta = 0: the true lengths
  // times beta are zero either way.
  const T bla = g.bt * g.la, blb = g.bt * g.lb;
  return {g.al * rax - bla * g.bx, g.al * ray - bla * g.by, g.al * raz - bla * g.bz,
          g.al * rbx - blb * g.ax, g.al * rby - blb * g.ay, g.al * rbz - blb * g.az};
}

// Transpose: dF/dra and dF/drb for F = ya.delta_a + yb.delta_b (derivation
// at CornerTranspose below).
template <typename T>
[[gnu::always_inline]] inline CornerTerms<T> TransposeTerms(T yax, T yay, T yaz, T ybx, T yby,
                                                            T ybz, const CornerGeometry<T>& g) {
  const T ax = g.ax, ay = g.ay, az = g.az, bx = g.bx, by = g.by, bz = g.bz;
  const T lra = g.la, lrb = g.lb, c = g.c;
  const T al = g.al, bt = g.bt;
  const T yab = yax * bx + yay * by + yaz * bz;
  const T yba = ybx * ax + yby * ay + ybz * az;
  const T pp = lra * (yax * ax + yay * ay + yaz * az) + lrb * (ybx * bx + yby * by + ybz * bz);
  const T qq = lra * yab + lrb * yba;
  const T coef = pp * g.dal - qq * g.dbt;
  // (With a zero side ia and ib are 0, and so are alpha, beta and their
  // derivatives: the terms are zero either way.)
  const T ka = -coef * g.inv_s * g.ia, kb = -coef * g.inv_s * g.ib;
  const T lba = lrb * g.ia, lab = lra * g.ib;
  return {ka * (bx - c * ax) + al * yax - bt * (yab * ax + lba * (ybx - yba * ax)),
          ka * (by - c * ay) + al * yay - bt * (yab * ay + lba * (yby - yba * ay)),
          ka * (bz - c * az) + al * yaz - bt * (yab * az + lba * (ybz - yba * az)),
          kb * (ax - c * bx) + al * ybx - bt * (yba * bx + lab * (yax - yab * bx)),
          kb * (ay - c * by) + al * yby - bt * (yba * by + lab * (yay - yab * by)),
          kb * (az - c * bz) + al * ybz - bt * (yba * bz + lab * (yaz - yab * bz))};
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

#ifdef DYNSOLID_MEASURE_AVX2
// Quadrilaterals q0 and q1's node rows of `base` as columns (lane k of
// register h: node k of quadrilateral h).
inline void LoadQuads(const double* base, const int32_t* v0, const int32_t* v1, Lanes& x,
                      Lanes& y, Lanes& z) {
  const int32_t* v[2] = {v0, v1};
  for (int h = 0; h < 2; ++h) {
    simd::RowsToColumns(simd::LoadRow(base, v[h][0]), simd::LoadRow(base, v[h][1]),
                        simd::LoadRow(base, v[h][2]), simd::LoadRow(base, v[h][3]), x.v[h],
                        y.v[h], z.v[h]);
  }
}

// Quadrilaterals q0 and q1's rest cosines (offset 0), sines (offset 4) or
// side rest lengths (offset 8):
// rows rest_id[q] of the measure's table of distinct rest corners.
inline Lanes LoadRest(const double* rest, const uint32_t* rest_id, int64_t q0, int64_t q1,
                      int offset) {
  return {_mm256_loadu_pd(rest + kQuadRestRow * static_cast<int64_t>(rest_id[q0]) + offset),
          _mm256_loadu_pd(rest + kQuadRestRow * static_cast<int64_t>(rest_id[q1]) + offset)};
}

// Adds lane k of register h of (x, y, z) to node v_h[k]'s row where bit k
// of owns_h is set (x and y in one 2-lane add, z alone: a 4-lane store
// would write the next row, which another part may own).
inline void AddQuads(double* out, const int32_t* v0, const int32_t* v1, uint8_t owns0,
                     uint8_t owns1, Lanes x, Lanes y, Lanes z) {
  const int32_t* v[2] = {v0, v1};
  const uint8_t owns[2] = {owns0, owns1};
  for (int h = 0; h < 2; ++h) {
    __m256d row[4];
    simd::ColumnsToRows(x.v[h], y.v[h], z.v[h], row);
    for (int k = 0; k < 4; ++k) {
      if (!(owns[h] & (1 << k))) continue;
      double* o = out + 3 * static_cast<int64_t>(v[h][k]);
      _mm_storeu_pd(o, _mm_add_pd(_mm_loadu_pd(o), _mm256_castpd256_pd128(row[k])));
      o[2] += _mm256_cvtsd_f64(_mm256_permute4x64_pd(row[k], 0x02));
    }
  }
}

// Corner k of a quadrilateral sits at node k, between a = node k - 1 and
// b = node k + 1: its sides are ra = Prev(p) - p, rb = Next(p) - p (the
// same differences, to the bit, as the per-corner path's a - n and b - n).
// Side b of corner k is side a of corner k + 1 reversed: one length and
// inverse per side, rotated into place (the same bits: the components are
// exact negatives).
struct QuadSides {
  Lanes rax, ray, raz, rbx, rby, rbz;
  Side<Lanes> a, b;
};
inline QuadSides Sides(Lanes x, Lanes y, Lanes z) {
  QuadSides r{Prev(x) - x, Prev(y) - y, Prev(z) - z, Next(x) - x, Next(y) - y, Next(z) - z,
              {}, {}};
  r.b = MeasureSide(r.rbx, r.rby, r.rbz);
  r.a = {Prev(r.b.l), Prev(r.b.inv)};
  return r;
}

constexpr int64_t kQuadsAhead = 16;

// Quadrilaterals two at a time; with an odd count the last runs as both
// halves, its second copy adding nothing (no owned nodes). Rows of the
// quadrilaterals kQuadsAhead further on are prefetched from each of
// `rows` (the node arrays read, and the output), so their misses overlap
// this pair's arithmetic.
template <typename Body>
void ForQuadPairs(const int32_t* qv, const uint8_t* owns, int64_t nq,
                  std::initializer_list<const double*> rows, Body body) {
  for (int64_t q = 0; q < nq; q += 2) {
    if (q + kQuadsAhead + 2 <= nq) {
      for (const int32_t* v = qv + 4 * (q + kQuadsAhead); v < qv + 4 * (q + kQuadsAhead + 2); ++v) {
        for (const double* base : rows) __builtin_prefetch(base + 3 * static_cast<int64_t>(*v));
      }
    }
    const int64_t q1 = q + 1 < nq ? q + 1 : q;
    body(q, q1, qv + 4 * q, qv + 4 * q1, owns[q], q1 != q ? owns[q1] : uint8_t{0});
  }
}

// Lane k all ones where side k of the quadrilateral carries its edge's
// term (bit 4 + k of its owns byte) and has a nonzero length.
inline Lanes SideEdges(uint8_t o0, uint8_t o1, Lanes length) {
  const __m256i bit = _mm256_setr_epi64x(1, 2, 4, 8);
  auto lanes = [&](uint8_t o) {
    const __m256i b = _mm256_and_si256(_mm256_set1_epi64x(o >> 4), bit);
    return _mm256_castsi256_pd(_mm256_cmpeq_epi64(b, bit));
  };
  return And(Lanes{lanes(o0), lanes(o1)}, Greater(length, Lanes(0.0)));
}

// Forward: node k takes corner k + 1's term on its a and corner k - 1's on
// its b, and the stretch terms of sides k - 1 (+, it is their j) and k
// (-, their i): side k's term is f r_b with f = (l - l0) / (2 l), exactly
// the edge list's (EdgeForward, with the side's inverse for the division).
void QuadsForward(const int32_t* qv, const double* rest, const uint32_t* rest_id,
                  const uint8_t* owns, int64_t nq, const double* pd, double* out) {
  ForQuadPairs(qv, owns, nq, {pd, out},
               [&](int64_t q0, int64_t q1, const int32_t* v0, const int32_t* v1, uint8_t o0,
                   uint8_t o1) {
                 Lanes x, y, z;
                 LoadQuads(pd, v0, v1, x, y, z);
                 const QuadSides r = Sides(x, y, z);
                 const CornerGeometry<Lanes> g = MeasureCorner<Lanes>(
                     r.rax, r.ray, r.raz, r.rbx, r.rby, r.rbz, r.a, r.b,
                     LoadRest(rest, rest_id, q0, q1, 0), LoadRest(rest, rest_id, q0, q1, 4));
                 const CornerTerms<Lanes> t =
                     ForwardTerms(r.rax, r.ray, r.raz, r.rbx, r.rby, r.rbz, g);
                 const Lanes l0 = LoadRest(rest, rest_id, q0, q1, 8);
                 const Lanes f = Select(SideEdges(o0, o1, r.b.l),
                                        Lanes(0.5) * (r.b.l - l0) * r.b.inv, Lanes(0.0));
                 const Lanes ex = f * r.rbx, ey = f * r.rby, ez = f * r.rbz;
                 AddQuads(out, v0, v1, o0, o1, Next(t.ax) + Prev(t.bx) + (Prev(ex) - ex),
                          Next(t.ay) + Prev(t.by) + (Prev(ey) - ey),
                          Next(t.az) + Prev(t.bz) + (Prev(ez) - ez));
               });
}

// Transpose: as the forward, plus minus both of its own corner's terms;
// side k's stretch term is c1 dy + c2 r_b with dy = y_{k+1} - y_k,
// c1 = (1 - l0 / l) / 2, c2 = l0 (r_b . dy) / (2 l^3) (EdgeTranspose).
void QuadsTranspose(const int32_t* qv, const double* rest, const uint32_t* rest_id,
                    const uint8_t* owns, int64_t nq, const double* pd, const double* py,
                    double* out) {
  ForQuadPairs(qv, owns, nq, {pd, py, out},
               [&](int64_t q0, int64_t q1, const int32_t* v0, const int32_t* v1, uint8_t o0,
                   uint8_t o1) {
                 Lanes x, y, z, yx, yy, yz;
                 LoadQuads(pd, v0, v1, x, y, z);
                 LoadQuads(py, v0, v1, yx, yy, yz);
                 const QuadSides r = Sides(x, y, z);
                 const CornerGeometry<Lanes> g = MeasureCorner<Lanes>(
                     r.rax, r.ray, r.raz, r.rbx, r.rby, r.rbz, r.a, r.b,
                     LoadRest(rest, rest_id, q0, q1, 0), LoadRest(rest, rest_id, q0, q1, 4));
                 const CornerTerms<Lanes> t = TransposeTerms(Prev(yx), Prev(yy), Prev(yz),
                                                             Next(yx), Next(yy), Next(yz), g);
                 const Lanes l0 = LoadRest(rest, rest_id, q0, q1, 8);
                 const Lanes on = SideEdges(o0, o1, r.b.l);
                 const Lanes il = r.b.inv;
                 const Lanes dx = Next(yx) - yx, dy = Next(yy) - yy, dz = Next(yz) - yz;
                 const Lanes rdy = r.rbx * dx + r.rby * dy + r.rbz * dz;
                 const Lanes c1 = Select(on, Lanes(0.5) * (Lanes(1.0) - l0 * il), Lanes(0.0));
                 const Lanes c2 =
                     Select(on, Lanes(0.5) * l0 * il * il * il * rdy, Lanes(0.0));
                 const Lanes ex = c1 * dx + c2 * r.rbx, ey = c1 * dy + c2 * r.rby,
                             ez = c1 * dz + c2 * r.rbz;
                 AddQuads(out, v0, v1, o0, o1,
                          Next(t.ax) + Prev(t.bx) - (t.ax + t.bx) + (Prev(ex) - ex),
                          Next(t.ay) + Prev(t.by) - (t.ay + t.by) + (Prev(ey) - ey),
                          Next(t.az) + Prev(t.bz) - (t.az + t.bz) + (Prev(ez) - ez));
               });
}
#else
// No quadrilaterals are built without AVX2 (kQuadLanes): nothing to add.
void QuadsForward(const int32_t*, const double*, const uint32_t*, const uint8_t*, int64_t,
                  const double*, double*) {}
void QuadsTranspose(const int32_t*, const double*, const uint32_t*, const uint8_t*, int64_t,
                    const double*, const double*, double*) {}
#endif

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
        QuadsForward(p.qv.data(), quad_rest_.data(), p.q_rest.data(), p.q_owns.data(),
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
        QuadsTranspose(p.qv.data(), quad_rest_.data(), p.q_rest.data(), p.q_owns.data(),
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
