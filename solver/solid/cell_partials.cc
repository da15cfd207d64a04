#include "solver/solid/cell_partials.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "solver/common/hash128.h"
#include "solver/fem/cubic_tensor.h"
#include "solver/fem/element_data.h"
#include "solver/models/gram.h"

namespace dynsolid::solid {

using SparseMatrix = subdivision::SparseMatrix;


struct MassPartials::Maker {
  // Per pool thread.
  struct Scratch {
    // W, kept from cell to cell (64-byte aligned for models::Gram).
    std::array<std::vector<double, models::GramAllocator>, 2> w;
    std::vector<double> root;              // sqrt(rho dV) per point
  };

  Maker(const models::ElementLayout& layout, bool has_damping, CellPoints& points, int threads)
      : layout(layout), points(points), has_damping(has_damping), scratch(threads) {
    for (const auto& array : layout.materials) {
      Hash128 h;
      for (const models::MaterialPoint& m : array) {
        h.Double(m.density);
        if (has_damping) h.Double(m.damping);
      }
      material_key.push_back(h.value());
    }
    spec.dofs = 1;
    spec.outputs = has_damping ? 2 : 1;
    spec.salt = 0x6d617373;  // "mass"
    spec.group_key = [this](int kind, int32_t gi) { return GroupKey(kind, gi); };
    spec.make_cell = [this](int t, const std::vector<int32_t>& support,
                            const std::vector<std::pair<int, int32_t>>& elements,
                            std::vector<Eigen::MatrixXd>& partial) {
      MakeCell(t, support, elements, partial);
    };
  }

  // A group's key: its kind, rest shape (the layout's rest key) and its
  // material array's densities (and dampings), each array hashed once.
  Key128 GroupKey(int kind, int32_t gi) const {
    const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
    Hash128 h;
    h.Mix(static_cast<uint64_t>(kind));
    h.Key(grp.rest_key);
    h.Key(material_key[grp.material]);
    return h.value();
  }

  // Whether every point of the cell has one damping / density ratio (then
  // Dt's partial is that ratio times Mt's: one Gram product, not two).
  std::pair<bool, double> DampingRatio(const std::vector<std::pair<int, int32_t>>& elements) const {
    bool first = true;
    double ratio = 0;
    for (const auto& [kind, e] : elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      for (const models::MaterialPoint& m : layout.materials[block.groups[block.group[e]].material]) {
        if (!(m.density > 0)) return {false, 0};
        const double r = m.damping / m.density;
        if (!first && r != ratio) return {false, 0};
        ratio = r;
        first = false;
      }
    }
    return {true, ratio};
  }

  void MakeCell(int t, const std::vector<int32_t>& support,
                const std::vector<std::pair<int, int32_t>>& elements,
                std::vector<Eigen::MatrixXd>& partial) {
    Scratch& sc = scratch[t];
    const std::vector<CellPoints::Element>& cell = points.Of(t, support, elements);
    const int s = static_cast<int>(support.size());
    int64_t points_in_cell = 0;
    for (const auto& [kind, e] : elements) points_in_cell += layout.tables[kind].points;
    // W's rows padded with zeros to a multiple of 8 (models::Gram's lanes).
    const int64_t rows = (points_in_cell + 7) / 8 * 8;
    const auto [proportional, ratio] =
        has_damping ? DampingRatio(elements) : std::pair<bool, double>{true, 0.0};
    const int ws = has_damping && !proportional ? 2 : 1;
    // W (rows x s, column major) per output; each element's rows written
    // in its support's columns and zeroed in the others.
    for (int o = 0; o < ws; ++o) {
      sc.w[o].resize(static_cast<size_t>(rows) * s);
      for (int c = 0; c < s; ++c) {
        std::fill(sc.w[o].data() + c * rows + points_in_cell, sc.w[o].data() + (c + 1) * rows, 0.0);
      }
    }
    int64_t row = 0;
    for (size_t i = 0; i < elements.size(); ++i) {
      const auto [kind, e] = elements[i];
      const models::ElementBlock& block = layout.blocks[kind];
      const fem::KindTable& table = layout.tables[kind];
      const ElementRows& er = *cell[i].rows;
      const auto& material = layout.materials[block.groups[block.group[e]].material];
      for (int32_t col : er.outside) {
        for (int o = 0; o < ws; ++o) {
          std::fill_n(sc.w[o].data() + static_cast<int64_t>(col) * rows + row, table.points, 0.0);
        }
      }
      const double* nb = points.Values(t, i);  // N B (Q x s_e)
      sc.root.resize(table.points);
      for (int o = 0; o < ws; ++o) {
        for (int q = 0; q < table.points; ++q) {
          const double value = o == 0 ? material[q].density : material[q].damping;
          sc.root[q] = std::sqrt(std::max(value * cell[i].dv[q], 0.0));
        }
        for (size_t a = 0; a < er.support.size(); ++a) {
          const double* from = nb + a * table.points;
          double* to = sc.w[o].data() + static_cast<int64_t>(er.support[a]) * rows + row;
          for (int q = 0; q < table.points; ++q) to[q] = sc.root[q] * from[q];
        }
      }
      row += table.points;
    }
    for (int o = 0; o < ws; ++o) models::Gram(sc.w[o].data(), rows, s, rows, partial[o].data(), s);
    if (has_damping && proportional) partial[1] = ratio * partial[0];
  }

  const models::ElementLayout& layout;
  CellPoints& points;
  const bool has_damping;
  std::vector<Key128> material_key;  // per material array
  CellSumSpec spec;
  std::vector<Scratch> scratch;
};

MassPartials::MassPartials(const models::ElementLayout& layout, bool has_damping,
                           CellPoints& points, int threads)
    : maker_(std::make_unique<Maker>(layout, has_damping, points, threads)) {}
MassPartials::~MassPartials() = default;
CellSumSpec& MassPartials::spec() { return maker_->spec; }

namespace {

// to[p] = sum over i < n, in order, of b[i] d[i stride + p], for p < q.
template <int Q>
void CombineColumns(const double* b, int n, const double* d, size_t stride, double* to) {
  double acc[Q];
  for (int p = 0; p < Q; ++p) acc[p] = b[0] * d[p];
  for (int i = 1; i < n; ++i) {
    const double* di = d + i * stride;
    for (int p = 0; p < Q; ++p) acc[p] = std::fma(b[i], di[p], acc[p]);
  }
  for (int p = 0; p < Q; ++p) to[p] = acc[p];
}
void CombineColumns(int q, const double* b, int n, const double* d, size_t stride, double* to) {
  for (int p = 0; p < q; ++p) to[p] = b[0] * d[p];
  for (int i = 1; i < n; ++i) {
    const double* di = d + i * stride;
    for (int p = 0; p < q; ++p) to[p] = std::fma(b[i], di[p], to[p]);
  }
}

}  // namespace

struct StiffnessPartials::Maker {
  struct Group {
    // 3Q x n column major, row k Q + q: (J_q^-T dN_q)_k times sqrt(dV mu)
    // (mu_d) and sqrt(dV lambda) (lambda_d) of point q. Cubic elements on
    // the 4-point rule have none: their parametric gradients are
    // sum-factorized (fem::CubicTensorProducts) and mu_jit, lambda_jit hold
    // the points' J_q^-T (entry (k, c) at [(3 k + c) Q + q]) times the
    // same roots.
    std::vector<double> mu_d, lambda_d;
    std::vector<double> mu_jit, lambda_jit;
    Eigen::VectorXd root_mu;   // Q: sqrt(dV mu)
    Eigen::VectorXd root_lambda;  // Q: sqrt(dV lambda)
  };
  // Per pool thread.
  struct Scratch {
    std::vector<double> p;  // a cubic element's parametric gradients (3 x 64 x s_e)
    std::vector<double> y;  // g_j's sums per FEM node (3 per node row of CellPoints)
    std::vector<double, models::GramAllocator> w, wl;  // 64-byte aligned for Gram
    // Per column of W, the 8-row chunks its rows may be nonzero in
    // (models::GramAddPanel): 3S words for the panel, then 3S for the rows
    // an element carries past the panel's end.
    std::vector<uint64_t> chunks;
    std::vector<double> g, gl, trace;
    Group group;  // the element's group data (GroupOf)
  };

  Maker(const models::ElementLayout& layout, const models::CorotationalModel& corotational,
        CellPoints& points, int threads)
      : points(points), scratch(threads) {
    spec.dofs = 3;
    spec.outputs = 1;
    spec.salt = 0x6b32;  // "k2": integrated at the points, summed per cell
    // A group's key: its kind, where the model applies it, its rest shape
    // (the layout's rest key) and its material array's Young's moduli and
    // Poisson ratios, each array hashed once.
    for (const auto& array : layout.materials) {
      Hash128 h;
      for (const models::MaterialPoint& m : array) {
        h.Double(m.young);
        h.Double(m.poisson);
      }
      material_key.push_back(h.value());
    }
    spec.group_key = [this, &layout, &corotational](int kind, int32_t gi) {
      const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
      Hash128 h;
      h.Mix(static_cast<uint64_t>(kind));
      h.Mix(corotational.at_quadrature_points(kind, gi) ? 1 : 0);
      h.Key(grp.rest_key);
      h.Key(material_key[grp.material]);
      return h.value();
    };
    spec.make_cell = [this, &layout](int t, const std::vector<int32_t>& support,
                                     const std::vector<std::pair<int, int32_t>>& elements,
                                     std::vector<Eigen::MatrixXd>& partial) {
      partial.emplace_back();
      MakeCell(layout, t, support, elements, partial[0], partial[1]);
    };
  }

  // Element e's group data (its points' `at`), made in the thread's
  // scratch, valid until the next call: the same for every element of the
  // group, and cheaper to make again (a few loops along the points) than
  // to keep per group (each kept group's rows took more time in fresh
  // pages than making them).
  const Group& GroupOf(const models::ElementLayout& layout, int kind, int32_t e,
                       const CellPoints::Element& at, bool uniform, Scratch& sc) {
    const bool factorized = kind == 0 && points.cubic_factorized();
    MakeGroup(layout, kind, layout.blocks[kind].group[e], factorized, !uniform, at, sc.group);
    return sc.group;
  }

  // Whether every point of e's material has one Poisson ratio, and
  // lambda / mu then (2 nu / (1 - 2 nu), from nu, so that groups of one nu
  // and different Young's moduli have the same ratio to the bit).
  static std::pair<bool, double> UniformRatio(const std::vector<models::MaterialPoint>& material) {
    bool same = !material.empty();
    for (size_t q = 1; q < material.size() && same; ++q) same = material[q].poisson == material[0].poisson;
    return {same, same ? 2 * material[0].poisson / (1 - 2 * material[0].poisson) : 0};
  }

  // A cell's K partial (3S square, given uncleared: written whole) and
  // its gradient weights g_j (S x 3): cell_partials.h.
  void MakeCell(const models::ElementLayout& layout, int t, const std::vector<int32_t>& support,
                const std::vector<std::pair<int, int32_t>>& elements, Eigen::MatrixXd& k,
                Eigen::MatrixXd& gradient) {
    const int s = static_cast<int>(support.size());
    gradient.setZero(s, 3);
    if (s == 0) return;
    Scratch& sc = scratch[t];
    const std::vector<CellPoints::Element>& cell = points.Of(t, support, elements);
    int most_points = 0;  // of an element
    bool uniform = true, first = true;
    double ratio = 0;
    for (const auto& [kind, e] : elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      most_points = std::max(most_points, layout.tables[kind].points);
      const auto [same, r] = UniformRatio(layout.materials[block.groups[block.group[e]].material]);
      if (!same || (!first && r != ratio)) uniform = false;
      ratio = r;
      first = false;
    }
    // Scratch that keeps its pages from cell to cell (a matrix resized to
    // each cell's size is new memory each time, every page a fault). W is
    // not cleared whole: each element's rows are written in its support's
    // columns and zeroed in the others (most of W is written); G is
    // written whole by Gram.
    auto sized = [](auto& buffer, int64_t r, int64_t c) {
      buffer.resize(static_cast<size_t>(r * c));
      return Eigen::Map<Eigen::MatrixXd>(buffer.data(), r, c);
    };
    // W is made a panel of rows at a time (models::GramAddPanel) and
    // summed into G = W^T W (and G_lambda) as each fills: a panel stays in
    // L2 between being written and read, where all of W (megabytes) went
    // out to memory and back. The panels are W's, whole (the same bits as
    // models::Gram of all of it): an element's rows past a panel's end
    // carry over to the next panel's start. Leading dimension a multiple
    // of 8 (aligned columns).
    const int64_t panel = models::kGramPanelRows;
    const int64_t ld = (panel + most_points + 7) / 8 * 8;  // room for an element past the end
    Eigen::Map<Eigen::MatrixXd> w = sized(sc.w, ld, 3 * s);
    Eigen::Map<Eigen::MatrixXd> wl = sized(sc.wl, uniform ? 0 : ld, 3 * s);
    Eigen::Map<Eigen::MatrixXd> gm = sized(sc.g, 3 * s, 3 * s);
    Eigen::Map<Eigen::MatrixXd> gl = sized(sc.gl, uniform ? 0 : 3 * s, 3 * s);
    models::GramStart(3 * s, gm.data(), 3 * s);
    if (!uniform) models::GramStart(3 * s, gl.data(), 3 * s);
    // Each element's rows are zero outside its support's columns: the Gram
    // skips the chunks of rows where a product's columns are not both
    // written (the same bits; near a local subdivision an element's
    // support is often a fraction of its cell's).
    sc.chunks.assign(static_cast<size_t>(6) * s, 0);
    uint64_t* carried = sc.chunks.data() + 3 * s;
    // Sums W's first `count` rows (a multiple of 8) into G, and moves the
    // rows after them, up to `row`, to the top.
    auto flush = [&](int64_t count, int64_t row) {
      models::GramAddPanel(w.data(), count, 3 * s, ld, sc.chunks.data(), gm.data(), 3 * s);
      if (!uniform) {
        models::GramAddPanel(wl.data(), count, 3 * s, ld, sc.chunks.data(), gl.data(), 3 * s);
      }
      // Rows carry over only past a whole panel.
      std::copy(carried, carried + 3 * s, sc.chunks.data());
      std::fill(carried, carried + 3 * s, 0);
      if (row == count) return;
      for (int c = 0; c < 3 * s; ++c) {
        std::copy(w.col(c).data() + count, w.col(c).data() + row, w.col(c).data());
        if (!uniform) std::copy(wl.col(c).data() + count, wl.col(c).data() + row, wl.col(c).data());
      }
    };
    int64_t row = 0;  // in the panel
    double volume = 0;
    int node_count = 0;
    const double* node_rows = points.NodeRows(t, &node_count);
    sc.y.assign(static_cast<size_t>(3) * node_count, 0.0);
    for (size_t i = 0; i < elements.size(); ++i) {
      const auto [kind, e] = elements[i];
      const Group& g = GroupOf(layout, kind, e, cell[i], uniform, sc);
      const models::ElementBlock& block = layout.blocks[kind];
      const ElementRows& er = *cell[i].rows;
      const int q = static_cast<int>(g.root_mu.size());
      // g_j: the element's physical gradients at its centre (the group's
      // rest shape) by det J there, summed and divided by the cell's
      // volume. Summed per FEM node first (Y), then through the node rows
      // once for the cell, below.
      const models::ElementGroup& grp = block.groups[block.group[e]];
      const double det = grp.centre_det;
      if (det > 0) {
        const int32_t* ids = block.element_nodes(e);
        for (int n = 0; n < block.nodes; ++n) {
          double* y = sc.y.data() + 3 * static_cast<size_t>(points.NodeRow(t, ids[n]));
          for (int c = 0; c < 3; ++c) y[c] = std::fma(det, grp.centre_gradient(n, c), y[c]);
        }
        volume += det;
      }
      if (row >= panel) {
        flush(panel, row);
        row -= panel;
      }
      for (int32_t col : er.outside) {
        for (int k = 0; k < 3; ++k) {
          std::fill_n(w.col(k * s + col).data() + row, q, 0.0);
          if (!uniform) std::fill_n(wl.col(k * s + col).data() + row, q, 0.0);
        }
      }
      {
        // The element's chunks, rows [row, row + q): in the panel's word
        // and, past its end, the carried word.
        uint64_t in_panel = 0, past = 0;
        for (int64_t c = row / 8; c <= (row + q - 1) / 8; ++c) {
          if (c < panel / 8) {
            in_panel |= uint64_t{1} << c;
          } else {
            past |= uint64_t{1} << (c - panel / 8);
          }
        }
        for (int32_t col : er.support) {
          for (int k = 0; k < 3; ++k) {
            sc.chunks[k * s + col] |= in_panel;
            carried[k * s + col] |= past;
          }
        }
      }
      if (kind == 0 && points.cubic_factorized()) {
        WriteCubicRows(t, i, er, g, uniform, s, row, sc, w, wl);
      } else {
        WriteRows(er, g, block.nodes, q, uniform, s, row, w, wl);
      }
      row += q;
    }
    CellGradient(node_rows, node_count, s, sc.y, volume, gradient);
    // The last panel, its rows padded with zeros to a multiple of 8 (they
    // add nothing); then G's (and G_lambda's) both triangles, and K column
    // by column.
    if (row >= panel) {
      flush(panel, row);
      row -= panel;
    }
    const int64_t padded = (row + 7) / 8 * 8;
    for (int c = 0; c < 3 * s; ++c) {
      std::fill(w.col(c).data() + row, w.col(c).data() + padded, 0.0);
      if (!uniform) std::fill(wl.col(c).data() + row, wl.col(c).data() + padded, 0.0);
    }
    if (padded > 0) flush(padded, padded);
    models::GramFinish(3 * s, gm.data(), 3 * s);
    if (!uniform) models::GramFinish(3 * s, gl.data(), 3 * s);
    AssembleK(s, uniform, ratio, gm, gl, sc.trace, k);
  }

  // g_j = (sum over nodes l of row_l^T Y_l) / volume: S x 3 from the
  // node rows (contiguous along the cell's columns).
  static void CellGradient(const double* node_rows, int node_count, int s,
                           const std::vector<double>& y_sums, double volume,
                           Eigen::MatrixXd& gradient) {
    for (int l = 0; l < node_count; ++l) {
      const double* from = node_rows + static_cast<size_t>(l) * s;
      for (int c = 0; c < 3; ++c) {
        const double y = y_sums[3 * static_cast<size_t>(l) + c];
        if (y == 0) continue;
        double* to = gradient.col(c).data();
        for (int a = 0; a < s; ++a) to[a] = std::fma(from[a], y, to[a]);
      }
    }
    if (volume > 0) gradient /= volume;
  }

  // W's rows of cubic element i of the cell (rows [row, row + 64) in the
  // support's columns), sum-factorized.
  void WriteCubicRows(int t, size_t i, const ElementRows& er, const Group& g, bool uniform, int s,
                      int64_t row, Scratch& sc, Eigen::Map<Eigen::MatrixXd>& w,
                      Eigen::Map<Eigen::MatrixXd>& wl) {
    const int se = static_cast<int>(er.support.size());
    // W's rows: sqrt(dV mu) J^-T (dN/du, dN/dv, dN/dw) B, the
    // parametric gradients of B's columns sum-factorized.
    sc.p.resize(static_cast<size_t>(3) * 64 * se);
    double* pu = sc.p.data();
    double* pv = pu + 64 * se;
    double* pw = pv + 64 * se;
    points.CubicDerivatives(t, i, pu);  // (and N B for the mass, on the way)
    for (int a = 0; a < se; ++a) {
      const int col = er.support[a];
      const double* du = pu + 64 * a;
      const double* dv = pv + 64 * a;
      const double* dw = pw + 64 * a;
      for (int pass = 0; pass < (uniform ? 1 : 2); ++pass) {
        const double* f = pass == 0 ? g.mu_jit.data() : g.lambda_jit.data();
        Eigen::Map<Eigen::MatrixXd>& into = pass == 0 ? w : wl;
        for (int k = 0; k < 3; ++k) {
          const double* f0 = f + (3 * k) * 64;
          const double* f1 = f0 + 64;
          const double* f2 = f1 + 64;
          double* to = into.col(k * s + col).data() + row;
          for (int p = 0; p < 64; ++p) {
            to[p] = std::fma(f2[p], dw[p], std::fma(f1[p], dv[p], f0[p] * du[p]));
          }
        }
      }
    }
  }

  // W's rows of an element of n nodes and q points (rows [row, row + q)
  // in the support's columns).
  static void WriteRows(const ElementRows& er, const Group& g, int n, int q, bool uniform, int s,
                        int64_t row, Eigen::Map<Eigen::MatrixXd>& w,
                        Eigen::Map<Eigen::MatrixXd>& wl) {
    const int se = static_cast<int>(er.support.size());
    // W's rows: column a of (root * D) B, as a sum of D's columns
    // weighted by B's entries in node order (runs of Q in SIMD lanes: no
    // per-entry dot products).
    const size_t rows3 = static_cast<size_t>(3) * q;
    for (int a = 0; a < se; ++a) {
      const int col = er.support[a];
      const double* b = er.values.data() + static_cast<size_t>(a) * n;
      for (int pass = 0; pass < (uniform ? 1 : 2); ++pass) {
        const double* d = pass == 0 ? g.mu_d.data() : g.lambda_d.data();
        Eigen::Map<Eigen::MatrixXd>& into = pass == 0 ? w : wl;
        for (int c = 0; c < 3; ++c) {
          double* to = into.col(c * s + col).data() + row;
          const double* dc = d + static_cast<size_t>(c) * q;
          if (q == 8) {
            CombineColumns<8>(b, n, dc, rows3, to);  // the trilinear rule: in registers
          } else {
            CombineColumns(q, b, n, dc, rows3, to);
          }
        }
      }
    }
  }

  // K column by column from G (and G_lambda when the cell's Poisson ratio
  // varies; else `ratio` times G), as cell_partials.h writes it: G's
  // (and G_lambda's) both triangles are there.
  static void AssembleK(int s, bool uniform, double ratio, const Eigen::Map<Eigen::MatrixXd>& gm,
                        const Eigen::Map<Eigen::MatrixXd>& gl, std::vector<double>& trace,
                        Eigen::MatrixXd& k) {
    trace.resize(s);
    for (int bb = 0; bb < s; ++bb) {
      const double* g0 = gm.col(bb).data();
      const double* g1 = gm.col(s + bb).data() + s;
      const double* g2 = gm.col(2 * s + bb).data() + 2 * s;
      for (int a = 0; a < s; ++a) trace[a] = g0[a] + g1[a] + g2[a];
      for (int dd = 0; dd < 3; ++dd) {
        double* out = k.col(3 * bb + dd).data();
        for (int c = 0; c < 3; ++c) {
          // Column dd s + bb of G (or G_lambda) at rows c s + a; column
          // c s + bb at rows dd s + a.
          const double* lambda_col = (uniform ? gm : gl).col(dd * s + bb).data() + c * s;
          const double* mu_col = gm.col(c * s + bb).data() + dd * s;
          for (int a = 0; a < s; ++a) {
            const double lambda_term = uniform ? ratio * lambda_col[a] : lambda_col[a];
            out[3 * a + c] = lambda_term + mu_col[a] + (c == dd ? trace[a] : 0.0);
          }
        }
      }
    }
  }

  // Group gi's data from its points' dV and J^-T (`at`, cell_partials.h);
  // the lambda rows only `with_lambda` (a cell of one Poisson ratio reads
  // none). Loops along the points, in SIMD lanes.
  static void MakeGroup(const models::ElementLayout& layout, int kind, int32_t gi, bool factorized,
                        bool with_lambda, const CellPoints::Element& at, Group& g) {
    const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
    const fem::KindTable& table = layout.tables[kind];
    const models::MaterialPoint* material = layout.materials[grp.material].data();
    const int n = table.nodes, points = table.points;
    g.root_mu.resize(points);
    g.root_lambda.resize(points);
    for (int q = 0; q < points; ++q) {
      g.root_mu[q] = std::sqrt(std::max(at.dv[q] * material[q].lame_mu(), 0.0));
    }
    if (with_lambda) {
      for (int q = 0; q < points; ++q) {
        g.root_lambda[q] = std::sqrt(std::max(at.dv[q] * material[q].lame_lambda(), 0.0));
      }
    }
    if (factorized) {
      g.mu_d.clear();
      g.lambda_d.clear();
      g.mu_jit.resize(static_cast<size_t>(9) * points);
      g.lambda_jit.resize(with_lambda ? static_cast<size_t>(9) * points : 0);
      // Entry (k, c) of J^-T at [(3 k + c) Q + q], times the point's root.
      for (int kc = 0; kc < 9; ++kc) {
        const double* jit = at.jit + static_cast<size_t>(kc) * points;
        double* mu = g.mu_jit.data() + static_cast<size_t>(kc) * points;
        for (int q = 0; q < points; ++q) mu[q] = g.root_mu[q] * jit[q];
        if (!with_lambda) continue;
        double* lambda = g.lambda_jit.data() + static_cast<size_t>(kc) * points;
        for (int q = 0; q < points; ++q) lambda[q] = g.root_lambda[q] * jit[q];
      }
      return;
    }
    const size_t rows3 = static_cast<size_t>(3) * points;
    g.mu_d.resize(rows3 * n);
    g.lambda_d.resize(with_lambda ? rows3 * n : 0);
    for (int q = 0; q < points; ++q) {
      const double* dn = table.dN(q);
      for (int k = 0; k < 3; ++k) {
        const double* jit_k = at.jit + static_cast<size_t>(3 * k) * points + q;  // (k, c) at c * points
        const double a = jit_k[0], b = jit_k[points], c = jit_k[2 * points];
        const size_t r = static_cast<size_t>(k) * points + q;
        for (int i = 0; i < n; ++i) {
          const double d = a * dn[3 * i] + b * dn[3 * i + 1] + c * dn[3 * i + 2];
          g.mu_d[i * rows3 + r] = g.root_mu[q] * d;
          if (with_lambda) g.lambda_d[i * rows3 + r] = g.root_lambda[q] * d;
        }
      }
    }
  }

  CellPoints& points;
  std::vector<Key128> material_key;  // per material array
  CellSumSpec spec;
  std::vector<Scratch> scratch;
};

StiffnessPartials::StiffnessPartials(const models::ElementLayout& layout,
                                     const models::CorotationalModel& corotational,
                                     CellPoints& points, int threads)
    : maker_(std::make_unique<Maker>(layout, corotational, points, threads)) {}
StiffnessPartials::~StiffnessPartials() = default;
CellSumSpec& StiffnessPartials::spec() { return maker_->spec; }

}  // namespace dynsolid::solid
