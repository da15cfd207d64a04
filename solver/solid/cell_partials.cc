#include "solver/solid/cell_partials.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "solver/common/hash128.h"
#include "solver/fem/cubic_tensor.h"
#include "solver/fem/element_data.h"

namespace dynsolid::solid {

using SparseMatrix = subdivision::SparseMatrix;

struct MassPartials::Maker {
  using Roots = std::array<std::vector<double>, 2>;  // sqrt(rho dV), sqrt(damping dV) per point
  // Per pool thread.
  struct Scratch {
    std::vector<int32_t> column, mark;  // control point -> cell column; GatherCellRows' marks
    ElementRows rows;
    Eigen::MatrixXd nb;                   // N B_e (Q x s_e)
    std::array<std::vector<double>, 2> w;  // W, kept from cell to cell
    std::vector<uint8_t> covered;         // per cell column: in the element's support
  };

  Maker(const models::ElementLayout& layout, const SparseMatrix& nm, bool has_damping, int threads)
      : layout(layout), nm(nm), has_damping(has_damping), outputs(has_damping ? 2 : 1),
        scratch(threads) {
    if (fem::CubicTensorProducts::Applies(layout.tables[0])) cubic.emplace(layout.tables[0]);
    for (int kind = 0; kind < 3; ++kind) {
      once[kind] = std::vector<std::once_flag>(layout.blocks[kind].groups.size());
      group_roots[kind].resize(layout.blocks[kind].groups.size());
    }
    spec.dofs = 1;
    spec.outputs = outputs;
    spec.salt = 0x6d617373;  // "mass"
    spec.group_key = [this](int kind, int32_t gi) { return GroupKey(kind, gi); };
    spec.make_cell = [this](int t, const std::vector<int32_t>& support,
                            const std::vector<std::pair<int, int32_t>>& elements,
                            std::vector<Eigen::MatrixXd>& partial) {
      MakeCell(scratch[t], support, elements, partial);
    };
  }

  Key128 GroupKey(int kind, int32_t gi) const {
    const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
    Hash128 h;
    h.Mix(static_cast<uint64_t>(kind));
    h.Doubles(grp.rest.data(), grp.rest.size());
    for (const models::MaterialPoint& m : layout.materials[grp.material]) {
      h.Double(m.density);
      if (has_damping) h.Double(m.damping);
    }
    return h.value();
  }

  // A group's roots, made when a cell first needs them.
  const Roots& RootsOf(int kind, int32_t gi) {
    std::call_once(once[kind][gi], [&] {
      const fem::KindTable& table = layout.tables[kind];
      const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
      const auto& material = layout.materials[grp.material];
      const int points = table.points;
      std::vector<double> j;
      fem::RestJacobians(table, grp.rest, j);
      Roots& out = group_roots[kind][gi];
      for (int o = 0; o < outputs; ++o) out[o].resize(points);
      for (int q = 0; q < points; ++q) {
        const double dv =
            std::max(fem::JacobianAt(j, points, q).determinant(), 0.0) * table.weight[q];
        out[0][q] = std::sqrt(std::max(material[q].density * dv, 0.0));
        if (has_damping) out[1][q] = std::sqrt(std::max(material[q].damping * dv, 0.0));
      }
    });
    return group_roots[kind][gi];
  }

  void MakeCell(Scratch& sc, const std::vector<int32_t>& support,
                const std::vector<std::pair<int, int32_t>>& elements,
                std::vector<Eigen::MatrixXd>& partial) {
    if (sc.column.empty()) sc.column.assign(nm.cols(), -1);
    const int s = static_cast<int>(support.size());
    int64_t rows = 0;
    for (const auto& [kind, e] : elements) rows += layout.tables[kind].points;
    // W (rows x s, column major) per output; each element's rows written
    // in its support's columns and zeroed in the others.
    for (int o = 0; o < outputs; ++o) sc.w[o].resize(static_cast<size_t>(rows) * s);
    for (int a = 0; a < s; ++a) sc.column[support[a]] = a;
    sc.mark.assign(s, -1);
    sc.covered.resize(s);
    int64_t row = 0;
    for (const auto& [kind, e] : elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      const fem::KindTable& table = layout.tables[kind];
      const Roots& roots = RootsOf(kind, block.group[e]);
      GatherCellRows(nm, block.element_nodes(e), block.nodes, sc.column, sc.mark, sc.rows);
      std::fill(sc.covered.begin(), sc.covered.end(), 0);
      for (int32_t col : sc.rows.support) sc.covered[col] = 1;
      for (int col = 0; col < s; ++col) {
        if (sc.covered[col]) continue;
        for (int o = 0; o < outputs; ++o) {
          std::fill_n(sc.w[o].data() + static_cast<int64_t>(col) * rows + row, table.points, 0.0);
        }
      }
      if (kind == 0 && cubic.has_value()) {
        sc.nb.resize(64, sc.rows.b.cols());
        cubic->Values(sc.rows.b.data(), 64, static_cast<int>(sc.rows.b.cols()), sc.nb.data(), 64);
      } else {
        const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>
            shape(table.n.data(), table.points, block.nodes);
        sc.nb.noalias() = shape * sc.rows.b;
      }
      for (size_t a = 0; a < sc.rows.support.size(); ++a) {
        const int col = sc.rows.support[a];
        const double* from = sc.nb.col(static_cast<Eigen::Index>(a)).data();
        for (int o = 0; o < outputs; ++o) {
          double* to = sc.w[o].data() + static_cast<int64_t>(col) * rows + row;
          for (int q = 0; q < table.points; ++q) to[q] = roots[o][q] * from[q];
        }
      }
      row += table.points;
    }
    for (int32_t c : support) sc.column[c] = -1;
    for (int o = 0; o < outputs; ++o) {
      Eigen::MatrixXd& p = partial[o];
      p.selfadjointView<Eigen::Lower>().rankUpdate(
          Eigen::Map<const Eigen::MatrixXd>(sc.w[o].data(), rows, s).transpose());
      p.triangularView<Eigen::StrictlyUpper>() = p.transpose();
    }
  }

  const models::ElementLayout& layout;
  const SparseMatrix& nm;
  const bool has_damping;
  const int outputs;
  CellSumSpec spec;
  std::optional<fem::CubicTensorProducts> cubic;  // N B sum-factorized (cubic_tensor.h)
  std::array<std::vector<std::once_flag>, 3> once;
  std::array<std::vector<Roots>, 3> group_roots;
  std::vector<Scratch> scratch;
};

MassPartials::MassPartials(const models::ElementLayout& layout, const SparseMatrix& nm,
                           bool has_damping, int threads)
    : maker_(std::make_unique<Maker>(layout, nm, has_damping, threads)) {}
MassPartials::~MassPartials() = default;
CellSumSpec& MassPartials::spec() { return maker_->spec; }

struct StiffnessPartials::Maker {
  struct Group {
    // 3Q x n, row k Q + q: (J_q^-T dN_q)_k. Cubic elements on the 4-point
    // rule have none: their parametric gradients are sum-factorized
    // (fem::CubicTensorProducts) and mu_jit, lambda_jit hold the points'
    // J_q^-T (entry (k, c) at [(3 k + c) Q + q]) times sqrt(dV mu) and
    // sqrt(dV lambda).
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> d;
    std::vector<double> mu_jit, lambda_jit;
    Eigen::VectorXd root_mu;   // Q: sqrt(dV mu)
    Eigen::VectorXd root_lambda;  // Q: sqrt(dV lambda)
    std::vector<double> j;        // (scratch: the rest Jacobians)
  };
  // Per pool thread.
  struct Scratch {
    std::vector<int32_t> column, mark;  // control point -> cell column; GatherCellRows' marks
    ElementRows rows;
    Eigen::MatrixXd h;
    Eigen::Matrix<double, Eigen::Dynamic, 3> ge;  // an element's share of g_j (s_e x 3)
    std::vector<double> p;  // a cubic element's parametric gradients (3 x 64 x s_e)
    std::vector<double> w, wl, g, gl;
    std::vector<uint8_t> covered;  // per cell column: in the element's support
    Group single;  // the group of one element (GroupOf)
  };

  Maker(const models::ElementLayout& layout, const models::CorotationalModel& corotational,
        const SparseMatrix& nm, int threads)
      : scratch(threads) {
    if (fem::CubicTensorProducts::Applies(layout.tables[0])) cubic.emplace(layout.tables[0]);
    for (int kind = 0; kind < 3; ++kind) {
      once[kind] = std::vector<std::once_flag>(layout.blocks[kind].groups.size());
      groups[kind].resize(layout.blocks[kind].groups.size());
    }
    spec.dofs = 3;
    spec.outputs = 1;
    spec.salt = 0x6b32;  // "k2": integrated at the points, summed per cell
    spec.group_key = [&layout, &corotational](int kind, int32_t gi) {
      const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
      Hash128 h;
      h.Mix(static_cast<uint64_t>(kind));
      h.Mix(corotational.at_quadrature_points(kind, gi) ? 1 : 0);
      h.Doubles(grp.rest.data(), grp.rest.size());
      for (const models::MaterialPoint& m : layout.materials[grp.material]) {
        h.Double(m.young);
        h.Double(m.poisson);
      }
      return h.value();
    };
    spec.make_cell = [this, &layout, &nm](int t, const std::vector<int32_t>& support,
                                          const std::vector<std::pair<int, int32_t>>& elements,
                                          std::vector<Eigen::MatrixXd>& partial) {
      partial.emplace_back();
      MakeCell(layout, nm, scratch[t], support, elements, partial[0], partial[1]);
    };
  }

  // Element e's group: made once and kept when the group has more than one
  // element, else made in the thread's scratch (an irregular region has a
  // group per element: keeping each one's 3Q x n gradients took more time
  // in fresh pages than making them).
  const Group& GroupOf(const models::ElementLayout& layout, int kind, int32_t e, Scratch& sc) {
    const models::ElementBlock& block = layout.blocks[kind];
    const int32_t gi = block.group[e];
    const bool factorized = kind == 0 && cubic.has_value();
    if (block.group_start[gi + 1] - block.group_start[gi] == 1) {
      MakeGroup(layout, kind, gi, factorized, sc.single);
      return sc.single;
    }
    std::call_once(once[kind][gi],
                   [&] { MakeGroup(layout, kind, gi, factorized, groups[kind][gi]); });
    return groups[kind][gi];
  }

  // Whether every point of e's material has one Poisson ratio, and
  // lambda / mu then (2 nu / (1 - 2 nu), from nu, so that groups of one nu
  // and different Young's moduli have the same ratio to the bit).
  static std::pair<bool, double> UniformRatio(const std::vector<models::MaterialPoint>& material) {
    bool same = !material.empty();
    for (size_t q = 1; q < material.size() && same; ++q) same = material[q].poisson == material[0].poisson;
    return {same, same ? 2 * material[0].poisson / (1 - 2 * material[0].poisson) : 0};
  }

  // A cell's K partial (3S square, given zero) and its gradient weights
  // g_j (S x 3): cell_partials.h.
  void MakeCell(const models::ElementLayout& layout, const SparseMatrix& nm, Scratch& sc,
                const std::vector<int32_t>& support,
                const std::vector<std::pair<int, int32_t>>& elements, Eigen::MatrixXd& k,
                Eigen::MatrixXd& gradient) {
    const int s = static_cast<int>(support.size());
    gradient.setZero(s, 3);
    if (s == 0) return;
    if (sc.column.empty()) sc.column.assign(nm.cols(), -1);
    int64_t rows = 0;
    bool uniform = true, first = true;
    double ratio = 0;
    for (const auto& [kind, e] : elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      rows += layout.tables[kind].points;
      const auto [same, r] = UniformRatio(layout.materials[block.groups[block.group[e]].material]);
      if (!same || (!first && r != ratio)) uniform = false;
      ratio = r;
      first = false;
    }
    // Scratch that keeps its pages from cell to cell (a matrix resized to
    // each cell's size is new memory each time, every page a fault).
    auto zeroed = [](std::vector<double>& buffer, int64_t r, int64_t c) {
      buffer.assign(static_cast<size_t>(r * c), 0.0);
      return Eigen::Map<Eigen::MatrixXd>(buffer.data(), r, c);
    };
    // W is not cleared whole: each element's rows are written in its
    // support's columns and zeroed in the others (most of W is written).
    auto sized = [](std::vector<double>& buffer, int64_t r, int64_t c) {
      buffer.resize(static_cast<size_t>(r * c));
      return Eigen::Map<Eigen::MatrixXd>(buffer.data(), r, c);
    };
    Eigen::Map<Eigen::MatrixXd> w = sized(sc.w, rows, 3 * s);
    Eigen::Map<Eigen::MatrixXd> wl = sized(sc.wl, uniform ? 0 : rows, 3 * s);
    for (int a = 0; a < s; ++a) sc.column[support[a]] = a;
    sc.mark.assign(s, -1);
    sc.covered.resize(s);
    int64_t row = 0;
    double volume = 0;
    for (const auto& [kind, e] : elements) {
      const Group& g = GroupOf(layout, kind, e, sc);
      const models::ElementBlock& block = layout.blocks[kind];
      GatherCellRows(nm, block.element_nodes(e), block.nodes, sc.column, sc.mark, sc.rows);
      const int q = static_cast<int>(g.root_mu.size());
      const int se = static_cast<int>(sc.rows.support.size());
      // g_j: the element's physical gradients at its centre (the group's
      // rest shape) by det J there, summed and divided by the cell's volume.
      const models::ElementGroup& grp = block.groups[block.group[e]];
      const double det =
          fem::RestJacobian(layout.tables[kind].centre_dn.data(), grp.rest, block.nodes).determinant();
      if (det > 0) {
        sc.ge.noalias() = sc.rows.b.transpose() * grp.centre_gradient;
        for (int a = 0; a < se; ++a) gradient.row(sc.rows.support[a]) += det * sc.ge.row(a);
        volume += det;
      }
      std::fill(sc.covered.begin(), sc.covered.end(), 0);
      for (int32_t col : sc.rows.support) sc.covered[col] = 1;
      for (int col = 0; col < s; ++col) {
        if (sc.covered[col]) continue;
        for (int k = 0; k < 3; ++k) {
          std::fill_n(w.col(k * s + col).data() + row, q, 0.0);
          if (!uniform) std::fill_n(wl.col(k * s + col).data() + row, q, 0.0);
        }
      }
      if (kind == 0 && cubic.has_value()) {
        // W's rows: sqrt(dV mu) J^-T (dN/du, dN/dv, dN/dw) B, the
        // parametric gradients of B's columns sum-factorized.
        sc.p.resize(static_cast<size_t>(3) * 64 * se);
        double* pu = sc.p.data();
        double* pv = pu + 64 * se;
        double* pw = pv + 64 * se;
        cubic->Derivatives(sc.rows.b.data(), 64, se, pu, pv, pw, 64);
        for (int a = 0; a < se; ++a) {
          const int col = sc.rows.support[a];
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
              for (int i = 0; i < 64; ++i) to[i] = f0[i] * du[i] + f1[i] * dv[i] + f2[i] * dw[i];
            }
          }
        }
        row += q;
        continue;
      }
      sc.h.noalias() = g.d * sc.rows.b;  // 3Q x s_e
      for (size_t a = 0; a < sc.rows.support.size(); ++a) {
        const int col = sc.rows.support[a];
        for (int c = 0; c < 3; ++c) {
          const double* from = sc.h.col(static_cast<Eigen::Index>(a)).data() + c * q;
          double* to = w.col(c * s + col).data() + row;
          for (int i = 0; i < q; ++i) to[i] = g.root_mu[i] * from[i];
          if (!uniform) {
            double* tol = wl.col(c * s + col).data() + row;
            for (int i = 0; i < q; ++i) tol[i] = g.root_lambda[i] * from[i];
          }
        }
      }
      row += q;
    }
    for (int32_t c : support) sc.column[c] = -1;
    if (volume > 0) gradient /= volume;
    Eigen::Map<Eigen::MatrixXd> gm = zeroed(sc.g, 3 * s, 3 * s);
    gm.selfadjointView<Eigen::Lower>().rankUpdate(w.transpose());
    if (!uniform) {
      zeroed(sc.gl, 3 * s, 3 * s).selfadjointView<Eigen::Lower>().rankUpdate(wl.transpose());
    }
    const Eigen::Map<const Eigen::MatrixXd> gl(sc.gl.data(), uniform ? 0 : 3 * s, 3 * s);
    auto at = [](const auto& m, int i, int j) { return i >= j ? m(i, j) : m(j, i); };
    for (int bb = 0; bb < s; ++bb) {
      for (int a = 0; a < s; ++a) {
        const double trace = at(gm, a, bb) + at(gm, s + a, s + bb) + at(gm, 2 * s + a, 2 * s + bb);
        for (int dd = 0; dd < 3; ++dd) {
          for (int c = 0; c < 3; ++c) {
            const double lambda_term = uniform ? ratio * at(gm, c * s + a, dd * s + bb)
                                               : at(gl, c * s + a, dd * s + bb);
            k(3 * a + c, 3 * bb + dd) =
                lambda_term + at(gm, dd * s + a, c * s + bb) + (c == dd ? trace : 0.0);
          }
        }
      }
    }
  }

  static void MakeGroup(const models::ElementLayout& layout, int kind, int32_t gi, bool factorized,
                        Group& g) {
    const models::ElementGroup& grp = layout.blocks[kind].groups[gi];
    const fem::KindTable& table = layout.tables[kind];
    const std::vector<models::MaterialPoint>& material = layout.materials[grp.material];
    const int n = table.nodes, points = table.points;
    if (factorized) {
      g.d.resize(0, 0);
      g.mu_jit.resize(static_cast<size_t>(9) * points);
      g.lambda_jit.resize(static_cast<size_t>(9) * points);
    } else {
      g.d.resize(3 * points, n);
    }
    g.root_mu.resize(points);
    g.root_lambda.resize(points);
    fem::RestJacobians(table, grp.rest, g.j);
    for (int q = 0; q < points; ++q) {
      const double* dn = table.dN(q);
      const Eigen::Matrix3d j = fem::JacobianAt(g.j, points, q);
      const double dv = std::max(j.determinant(), 0.0) * table.weight[q];
      const Eigen::Matrix3d jit =
          dv > 0 ? Eigen::Matrix3d(j.inverse().transpose()) : Eigen::Matrix3d::Zero();
      g.root_mu[q] = std::sqrt(std::max(dv * material[q].lame_mu(), 0.0));
      g.root_lambda[q] = std::sqrt(std::max(dv * material[q].lame_lambda(), 0.0));
      for (int k = 0; k < 3; ++k) {
        const double a = jit(k, 0), b = jit(k, 1), c = jit(k, 2);
        if (factorized) {
          for (int cc = 0; cc < 3; ++cc) {
            g.mu_jit[(3 * k + cc) * points + q] = g.root_mu[q] * jit(k, cc);
            g.lambda_jit[(3 * k + cc) * points + q] = g.root_lambda[q] * jit(k, cc);
          }
          continue;
        }
        double* row = g.d.row(k * points + q).data();  // contiguous: d is row major
        for (int i = 0; i < n; ++i) row[i] = a * dn[3 * i] + b * dn[3 * i + 1] + c * dn[3 * i + 2];
      }
    }
  }

  CellSumSpec spec;
  std::optional<fem::CubicTensorProducts> cubic;  // when the cubic table is on the 4-point rule
  std::vector<Scratch> scratch;
  std::array<std::vector<std::once_flag>, 3> once;
  std::array<std::vector<Group>, 3> groups;
};

StiffnessPartials::StiffnessPartials(const models::ElementLayout& layout,
                                     const models::CorotationalModel& corotational,
                                     const SparseMatrix& nm, int threads)
    : maker_(std::make_unique<Maker>(layout, corotational, nm, threads)) {}
StiffnessPartials::~StiffnessPartials() = default;
CellSumSpec& StiffnessPartials::spec() { return maker_->spec; }

}  // namespace dynsolid::solid
