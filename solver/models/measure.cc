#include "solver/models/measure.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <Eigen/Geometry>

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
                                       int parts) {
  std::vector<Edge> edges;
  std::vector<Corner> corners;
  edges.reserve(mesh.num_edges());
  for (int32_t e = 0; e < mesh.num_edges(); ++e) {
    const auto& ev = mesh.edge_vertices(e);
    AddEdge(ev[0], ev[1], rest, edges);
  }
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const auto loop = mesh.face_vertices(f);
    const size_t k = loop.size();
    for (size_t i = 0; i < k; ++i) {
      AddCorner(loop[i], loop[(i + k - 1) % k], loop[(i + 1) % k], rest, corners);
    }
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
  for (const Edge& edge : edges) {
    const int ks[2] = {owner_[edge.i], owner_[edge.j]};
    for (int t = 0; t < 2; ++t) {
      if (!distinct(ks, t)) continue;
      Part& p = parts_[ks[t]];
      p.ei.push_back(edge.i);
      p.ej.push_back(edge.j);
      p.e_rest.push_back(edge.rest_length);
      p.e_owns.push_back((ks[0] == ks[t] ? 1 : 0) | (ks[1] == ks[t] ? 2 : 0));
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
  num_corners_ = static_cast<int64_t>(corners.size());
  for (Part& p : parts_) {
    for (auto* v : {&p.nodes, &p.ei, &p.ej, &p.cn, &p.ca, &p.cb}) v->shrink_to_fit();
    for (auto* v : {&p.e_rest, &p.cos0, &p.sin0}) v->shrink_to_fit();
    p.e_owns.shrink_to_fit();
    p.c_owns.shrink_to_fit();
  }
}

int64_t DeformationMeasure::bytes() const {
  auto b = [](const auto& v) { return static_cast<int64_t>(v.size() * sizeof(v[0])); };
  int64_t n = b(owner_);
  for (const Part& p : parts_) {
    n += b(p.nodes) + b(p.ei) + b(p.ej) + b(p.e_rest) + b(p.e_owns) + b(p.cn) + b(p.ca) +
         b(p.cb) + b(p.cos0) + b(p.sin0) + b(p.c_owns);
  }
  return n;
}

int64_t DeformationMeasure::terms_per_pass() const {
  int64_t n = 0;
  for (const Part& p : parts_) n += static_cast<int64_t>(p.ei.size() + p.cn.size());
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
                 const double* R rest, double* R fx, double* R fy, double* R fz, int64_t ne) {
  for (int64_t q = 0; q < ne; ++q) {
    const int64_t i = 3 * static_cast<int64_t>(ei[q]), j = 3 * static_cast<int64_t>(ej[q]);
    const double x = pd[j] - pd[i], y = pd[j + 1] - pd[i + 1], z = pd[j + 2] - pd[i + 2];
    const double len = std::sqrt(x * x + y * y + z * z);
    const double f_any = 0.5 * (len - rest[q]) / (len > 0 ? len : 1.0);
    const double f = len > 0 ? f_any : 0.0;
    fx[q] = f * x;
    fy[q] = f * y;
    fz[q] = f * z;
  }
}

// Corner geometry (n; a, b) from ra = a - n and rb = b - n: with
// phi = (theta - theta0) / 2, C = cos(phi), S = sin(phi), rotating a by
// +phi and b by -phi about n gives delta_a = alpha ra - beta la b^ and
// delta_b = alpha rb - beta lb a^, alpha = 1 - C + c S / s, beta = S / s
// (c, s the cosine and sine of the current angle). A degenerate corner (a
// zero side, collinear sides, or an angle half a turn from its rest value)
// contributes nothing: its alpha, beta and their derivatives in theta are
// zero and its other values finite.
struct CornerGeometry {
  double ax, ay, az, bx, by, bz;  // unit sides a^, b^
  double la, lb;                  // side lengths (1 for a zero side)
  double c, inv_s;                // cos theta, 1 / sin theta
  double al, bt, dal, dbt;        // alpha, beta and their theta derivatives
};

[[gnu::always_inline]] inline CornerGeometry MeasureCorner(double rax, double ray, double raz,
                                                           double rbx, double rby, double rbz,
                                                           double cos0, double sin0) {
  CornerGeometry g;
  const double lra = std::sqrt(rax * rax + ray * ray + raz * raz);
  const double lrb = std::sqrt(rbx * rbx + rby * rby + rbz * rbz);
  // Validity as 0/1 doubles (bool lanes keep GCC from vectorizing).
  const double sides = std::min(lra, lrb) > 0 ? 1.0 : 0.0;
  const double ia_any = 1.0 / (sides > 0 ? lra : 1.0), ib_any = 1.0 / (sides > 0 ? lrb : 1.0);
  const double ia = sides > 0 ? ia_any : 0.0, ib = sides > 0 ? ib_any : 0.0;
  g.ax = rax * ia, g.ay = ray * ia, g.az = raz * ia;
  g.bx = rbx * ib, g.by = rby * ib, g.bz = rbz * ib;
  const double c = g.ax * g.bx + g.ay * g.by + g.az * g.bz;
  const double x0 = g.ay * g.bz - g.az * g.by, x1 = g.az * g.bx - g.ax * g.bz,
               x2 = g.ax * g.by - g.ay * g.bx;
  const double sn = std::sqrt(x0 * x0 + x1 * x1 + x2 * x2);
  // phi in (-pi/2, pi/2) by half-angle formulas.
  const double cos_d = c * cos0 + sn * sin0;
  const double sin_d = sn * cos0 - c * sin0;
  const double cap_c = std::sqrt(std::max(0.0, 0.5 * (1.0 + cos_d)));
  const double ok_s = sn > 1e-300 ? sides : 0.0;
  const double okf = cap_c >= 1e-12 ? ok_s : 0.0;
  const double s_safe = okf > 0 ? sn : 1.0, c_safe = okf > 0 ? cap_c : 1.0;
  const double is = 1.0 / s_safe;
  const double cap_s = sin_d / (2.0 * c_safe);
  const double bt_any = cap_s * is;
  const double al_any = 1.0 - c_safe + c * bt_any;
  const double dal_any = -0.5 * cap_s + c * c_safe * 0.5 * is - c * c * cap_s * is * is;
  const double dbt_any = c_safe * 0.5 * is - cap_s * c * is * is;
  g.bt = okf > 0 ? bt_any : 0.0;
  g.al = okf > 0 ? al_any : 0.0;
  g.dal = okf > 0 ? dal_any : 0.0;
  g.dbt = okf > 0 ? dbt_any : 0.0;
  g.la = sides > 0 ? lra : 1.0;
  g.lb = sides > 0 ? lrb : 1.0;
  g.c = c;
  g.inv_s = is;
  return g;
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
    const CornerGeometry g = MeasureCorner(rax, ray, raz, rbx, rby, rbz, cos0[q], sin0[q]);
    // With a zero side, la/lb hold 1 but alpha = beta = 0: the true lengths
    // times beta are zero either way.
    const double bla = g.bt * g.la, blb = g.bt * g.lb;
    tax[q] = g.al * rax - bla * g.bx;
    tay[q] = g.al * ray - bla * g.by;
    taz[q] = g.al * raz - bla * g.bz;
    tbx[q] = g.al * rbx - blb * g.ax;
    tby[q] = g.al * rby - blb * g.ay;
    tbz[q] = g.al * rbz - blb * g.az;
  }
}

// Edge (i, j): c = 1/2 (1 - l0 / l) r with r = d_j - d_i adds to delta_j and
// subtracts from delta_i, so d/dr of (y_j - y_i) . c is
// J (y_j - y_i) with J = 1/2 [(1 - l0/l) I + (l0 / l^3) r r^T].
void EdgeTranspose(const double* R pd, const double* R py, const int32_t* R ei,
                   const int32_t* R ej, const double* R rest, double* R fx, double* R fy,
                   double* R fz, int64_t ne) {
  for (int64_t q = 0; q < ne; ++q) {
    const int64_t i = 3 * static_cast<int64_t>(ei[q]), j = 3 * static_cast<int64_t>(ej[q]);
    const double rx = pd[j] - pd[i], ry = pd[j + 1] - pd[i + 1], rz = pd[j + 2] - pd[i + 2];
    const double len = std::sqrt(rx * rx + ry * ry + rz * rz);
    const double dx = py[j] - py[i], dy = py[j + 1] - py[i + 1], dz = py[j + 2] - py[i + 2];
    const bool ok = len > 0;
    const double il = 1.0 / (ok ? len : 1.0);
    const double rdy = rx * dx + ry * dy + rz * dz;
    const double c1_any = 0.5 * (1.0 - rest[q] * il);
    const double c2_any = 0.5 * rest[q] * il * il * il * rdy;
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
    const CornerGeometry g = MeasureCorner(rax, ray, raz, rbx, rby, rbz, cos0[q], sin0[q]);
    const double yax = py[a], yay = py[a + 1], yaz = py[a + 2];
    const double ybx = py[b], yby = py[b + 1], ybz = py[b + 2];
    const double ax = g.ax, ay = g.ay, az = g.az, bx = g.bx, by = g.by, bz = g.bz;
    const double lra = g.la, lrb = g.lb, c = g.c;
    const double al = g.al, bt = g.bt;
    const double yab = yax * bx + yay * by + yaz * bz;
    const double yba = ybx * ax + yby * ay + ybz * az;
    const double pp =
        lra * (yax * ax + yay * ay + yaz * az) + lrb * (ybx * bx + yby * by + ybz * bz);
    const double qq = lra * yab + lrb * yba;
    const double coef = pp * g.dal - qq * g.dbt;
    const double ka = -coef * g.inv_s / lra, kb = -coef * g.inv_s / lrb;
    const double lba = lrb / lra, lab = lra / lrb;
    tax[q] = ka * (bx - c * ax) + al * yax - bt * (yab * ax + lba * (ybx - yba * ax));
    tay[q] = ka * (by - c * ay) + al * yay - bt * (yab * ay + lba * (yby - yba * ay));
    taz[q] = ka * (bz - c * az) + al * yaz - bt * (yab * az + lba * (ybz - yba * az));
    tbx[q] = kb * (ax - c * bx) + al * ybx - bt * (yba * bx + lab * (yax - yab * bx));
    tby[q] = kb * (ay - c * by) + al * yby - bt * (yba * by + lab * (yay - yab * by));
    tbz[q] = kb * (az - c * bz) + al * ybz - bt * (yba * bz + lab * (yaz - yab * bz));
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

template <typename EdgeTerms, typename CornerTerms>
void DeformationMeasure::RunPart(const Part& p, bool centres, double* out, EdgeTerms edge_terms,
                                 CornerTerms corner_terms) {
  for (int32_t v : p.nodes) out[3 * v] = out[3 * v + 1] = out[3 * v + 2] = 0;
  ChunkTerms t;
  const int64_t ne = static_cast<int64_t>(p.ei.size());
  for (int64_t q0 = 0; q0 < ne; q0 += kChunk) {
    const int64_t m = std::min(kChunk, ne - q0);
    edge_terms(q0, m, t.x0, t.y0, t.z0);
    for (int64_t u = 0; u < m; ++u) {
      const uint8_t owns = p.e_owns[q0 + u];
      if (owns & 1) AddRow(out, p.ei[q0 + u], -t.x0[u], -t.y0[u], -t.z0[u]);
      if (owns & 2) AddRow(out, p.ej[q0 + u], t.x0[u], t.y0[u], t.z0[u]);
    }
  }
  const int64_t nc = static_cast<int64_t>(p.cn.size());
  for (int64_t q0 = 0; q0 < nc; q0 += kChunk) {
    const int64_t m = std::min(kChunk, nc - q0);
    corner_terms(q0, m, t.x0, t.y0, t.z0, t.x1, t.y1, t.z1);
    for (int64_t u = 0; u < m; ++u) {
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
      p, /*centres=*/false, delta.data(),
      [&](int64_t q0, int64_t m, double* fx, double* fy, double* fz) {
        EdgeForward(pd, p.ei.data() + q0, p.ej.data() + q0, p.e_rest.data() + q0, fx, fy, fz, m);
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
      p, /*centres=*/true, out.data(),
      [&](int64_t q0, int64_t m, double* fx, double* fy, double* fz) {
        EdgeTranspose(pd, py, p.ei.data() + q0, p.ej.data() + q0, p.e_rest.data() + q0, fx, fy,
                      fz, m);
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
