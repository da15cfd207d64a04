// The points of a control cell's elements and their rows of the node
// matrix, numbered within the cell (cell_partials.h CellPoints), for the
// mass and stiffness partials.
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

struct CellPoints::Impl {
  // A shape's points: dV and J^-T (CellPoints::Element).
  struct Rest {
    std::vector<double> dv, jit;
  };
  // Per pool thread: the cell last asked for.
  struct Thread {
    std::vector<std::pair<int, int32_t>> elements;  // its elements (empty: none yet)
    std::vector<int32_t> support;
    std::vector<ElementRows> rows;
    std::vector<Rest> own;  // per element of the cell whose group has one element
    std::vector<Element> out;
    std::vector<int32_t> column;        // control point -> cell column
    std::vector<double> j;              // rest Jacobians (scratch)
    // The cell's distinct FEM nodes: their rows dense on the cell's columns
    // (row major) and which columns each touches (bit masks).
    std::vector<int32_t> nodes, local, stamp;  // local[node]: its row, when stamp[node] == serial
    int32_t serial = 0;
    std::vector<double> table;
    std::vector<uint64_t> masks, element_mask;
    // Per element of the cell: N B (Q x s_e), once made.
    std::vector<std::vector<double>> values;
    std::vector<uint8_t> has_values;
  };

  Impl(const models::ElementLayout& layout, const SparseMatrix& nm, int threads)
      : layout(layout), nm(nm), thread(threads) {
    if (fem::CubicTensorProducts::Applies(layout.tables[0])) cubic.emplace(layout.tables[0]);
    for (int kind = 0; kind < fem::kElementKinds; ++kind) {
      once[kind] = std::vector<std::once_flag>(layout.blocks[kind].groups.size());
      shared[kind].resize(layout.blocks[kind].groups.size());
    }
  }

  // dV = max(det J, 0) w and J^-T (zero where dV is 0) at the points of
  // group gi's rest shape.
  void MakeRest(int kind, int32_t gi, std::vector<double>& j, Rest& r) const {
    const fem::KindTable& table = layout.tables[kind];
    const int points = table.points;
    const fem::NodeMatrixX3& rest = layout.blocks[kind].groups[gi].rest;
    if (kind == 0 && cubic.has_value()) {
      cubic->Jacobians(rest, j);  // sum-factorized: a sixth of the multiply-adds
    } else {
      fem::RestJacobians(table, rest, j);
    }
    r.dv.resize(points);
    r.jit.resize(static_cast<size_t>(9) * points);
    // Point by point from the entries' rows of j (entry (a, b) of J_q at
    // [(3 a + b) points + q]), straight-line so that the loop runs in SIMD
    // lanes: J^-T = cofactors / det.
    const double* e[9];
    double* t[9];
    for (int k = 0; k < 9; ++k) {
      e[k] = j.data() + static_cast<size_t>(k) * points;
      t[k] = r.jit.data() + static_cast<size_t>(k) * points;
    }
    for (int q = 0; q < points; ++q) {
      const double j00 = e[0][q], j01 = e[1][q], j02 = e[2][q];
      const double j10 = e[3][q], j11 = e[4][q], j12 = e[5][q];
      const double j20 = e[6][q], j21 = e[7][q], j22 = e[8][q];
      const double c00 = j11 * j22 - j12 * j21, c01 = j12 * j20 - j10 * j22,
                   c02 = j10 * j21 - j11 * j20;
      const double det = j00 * c00 + j01 * c01 + j02 * c02;
      const double dv = std::max(det, 0.0) * table.weight[q];
      const double inv = dv > 0 ? 1.0 / det : 0.0;
      r.dv[q] = dv;
      t[0][q] = c00 * inv;
      t[1][q] = c01 * inv;
      t[2][q] = c02 * inv;
      t[3][q] = (j02 * j21 - j01 * j22) * inv;
      t[4][q] = (j00 * j22 - j02 * j20) * inv;
      t[5][q] = (j01 * j20 - j00 * j21) * inv;
      t[6][q] = (j01 * j12 - j02 * j11) * inv;
      t[7][q] = (j02 * j10 - j00 * j12) * inv;
      t[8][q] = (j00 * j11 - j01 * j10) * inv;
    }
  }

  const std::vector<Element>& Of(int t, const std::vector<int32_t>& support,
                                 const std::vector<std::pair<int, int32_t>>& elements) {
    Thread& th = thread[t];
    if (!th.elements.empty() && th.elements == elements && th.support == support) return th.out;
    th.elements = elements;
    th.support = support;
    if (th.column.empty()) {
      th.column.assign(nm.cols(), -1);
      th.stamp.assign(nm.rows(), 0);
      th.local.assign(nm.rows(), -1);
    }
    const int s = static_cast<int>(support.size());
    const int words = (s + 63) / 64;
    for (int a = 0; a < s; ++a) th.column[support[a]] = a;
    // Each distinct node's row once, dense on the cell's columns (elements
    // of a cell share most of their nodes).
    ++th.serial;
    th.nodes.clear();
    for (const auto& [kind, e] : elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      const int32_t* ids = block.element_nodes(e);
      for (int k = 0; k < block.nodes; ++k) {
        if (th.stamp[ids[k]] == th.serial) continue;
        th.stamp[ids[k]] = th.serial;
        th.local[ids[k]] = static_cast<int32_t>(th.nodes.size());
        th.nodes.push_back(ids[k]);
      }
    }
    th.table.assign(th.nodes.size() * s, 0.0);
    th.masks.assign(th.nodes.size() * words, 0);
    for (size_t l = 0; l < th.nodes.size(); ++l) {
      for (SparseMatrix::InnerIterator it(nm, th.nodes[l]); it; ++it) {
        const int32_t col = th.column[it.col()];
        th.table[l * s + col] = it.value();
        th.masks[l * words + col / 64] |= uint64_t{1} << (col % 64);
      }
    }
    const size_t n = elements.size();
    if (th.rows.size() < n) th.rows.resize(n);
    if (th.own.size() < n) th.own.resize(n);
    if (th.values.size() < n) th.values.resize(n);
    th.has_values.assign(n, 0);
    th.out.resize(n);
    for (size_t i = 0; i < n; ++i) {
      const auto [kind, e] = elements[i];
      const models::ElementBlock& block = layout.blocks[kind];
      // The element's rows on the cell columns its nodes touch, from the
      // table.
      const int32_t* ids = block.element_nodes(e);
      th.element_mask.assign(words, 0);
      for (int k = 0; k < block.nodes; ++k) {
        const uint64_t* m = th.masks.data() + static_cast<size_t>(th.local[ids[k]]) * words;
        for (int w = 0; w < words; ++w) th.element_mask[w] |= m[w];
      }
      ElementRows& er = th.rows[i];
      er.support.clear();
      er.outside.clear();
      for (int w = 0; w < words; ++w) {
        for (uint64_t bits = th.element_mask[w]; bits != 0; bits &= bits - 1) {
          er.support.push_back(64 * w + std::countr_zero(bits));
        }
        const int in_word = std::min(64, s - 64 * w);
        const uint64_t all = in_word == 64 ? ~uint64_t{0} : (uint64_t{1} << in_word) - 1;
        for (uint64_t bits = ~th.element_mask[w] & all; bits != 0; bits &= bits - 1) {
          er.outside.push_back(64 * w + std::countr_zero(bits));
        }
      }
      const int se = static_cast<int>(er.support.size());
      // Node by node: each node's table row read along (an L1-resident
      // B written across), not each column down the table's rows (a
      // cache line per entry).
      er.nodes = block.nodes;
      er.values.resize(static_cast<size_t>(block.nodes) * se);
      const int32_t* cols = er.support.data();
      for (int k = 0; k < block.nodes; ++k) {
        const double* from = th.table.data() + static_cast<size_t>(th.local[ids[k]]) * s;
        double* to = er.values.data() + k;
        for (int a = 0; a < se; ++a) to[static_cast<size_t>(a) * block.nodes] = from[cols[a]];
      }
      // Groups of several elements keep their points' data for the build;
      // an irregular region's groups of one are made in the thread's
      // scratch (keeping each one's took more time in fresh pages).
      const int32_t gi = block.group[e];
      const Rest* rest = &th.own[i];
      if (block.group_start[gi + 1] - block.group_start[gi] == 1) {
        MakeRest(kind, gi, th.j, th.own[i]);
      } else {
        // (A copy of the binding: clang before 16 cannot capture one.)
        const int k_kind = kind;
        std::call_once(once[kind][gi], [&] {
          std::vector<double> j;
          MakeRest(k_kind, gi, j, shared[k_kind][gi]);
        });
        rest = &shared[kind][gi];
      }
      th.out[i] = Element{&th.rows[i], rest->dv.data(), rest->jit.data()};
    }
    for (int32_t c : support) th.column[c] = -1;
    return th.out;
  }

  const double* Values(int t, size_t i) {
    Thread& th = thread[t];
    std::vector<double>& out = th.values[i];
    if (th.has_values[i]) return out.data();
    const auto [kind, e] = th.elements[i];
    const fem::KindTable& table = layout.tables[kind];
    const ElementRows& er = th.rows[i];
    out.resize(static_cast<size_t>(table.points) * er.support.size());
    if (kind == 0 && cubic.has_value()) {
      cubic->Values(er.values.data(), 64, static_cast<int>(er.support.size()), out.data(), 64);
    } else {
      const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>
          shape(table.n.data(), table.points, table.nodes);
      Eigen::Map<Eigen::MatrixXd>(out.data(), table.points, er.support.size()).noalias() =
          shape * er.b();
    }
    th.has_values[i] = 1;
    return out.data();
  }

  void CubicDerivatives(int t, size_t i, double* out) {
    Thread& th = thread[t];
    const ElementRows& er = th.rows[i];
    const int se = static_cast<int>(er.support.size());
    double* values = nullptr;
    if (!th.has_values[i]) {
      th.values[i].resize(static_cast<size_t>(64) * se);
      values = th.values[i].data();
      th.has_values[i] = 1;
    }
    cubic->Derivatives(er.values.data(), 64, se, out, out + 64 * se, out + 128 * se, 64, values);
  }

  const models::ElementLayout& layout;
  const SparseMatrix& nm;
  std::optional<fem::CubicTensorProducts> cubic;  // when the cubic table is on the 4-point rule
  std::vector<Thread> thread;
  std::array<std::vector<std::once_flag>, 3> once;
  std::array<std::vector<Rest>, 3> shared;
};

CellPoints::CellPoints(const models::ElementLayout& layout, const SparseMatrix& nm, int threads)
    : impl_(std::make_unique<Impl>(layout, nm, threads)) {}
CellPoints::~CellPoints() = default;
const std::vector<CellPoints::Element>& CellPoints::Of(
    int thread, const std::vector<int32_t>& support,
    const std::vector<std::pair<int, int32_t>>& elements) {
  return impl_->Of(thread, support, elements);
}
bool CellPoints::cubic_factorized() const { return impl_->cubic.has_value(); }
const double* CellPoints::NodeRows(int thread, int* count) const {
  const Impl::Thread& th = impl_->thread[thread];
  *count = static_cast<int>(th.nodes.size());
  return th.table.data();
}
int32_t CellPoints::NodeRow(int thread, int32_t node) const {
  return impl_->thread[thread].local[node];
}
const double* CellPoints::Values(int thread, size_t i) { return impl_->Values(thread, i); }
void CellPoints::CubicDerivatives(int thread, size_t i, double* out) {
  impl_->CubicDerivatives(thread, i, out);
}

}  // namespace dynsolid::solid
