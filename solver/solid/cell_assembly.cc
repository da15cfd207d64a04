#include "solver/solid/cell_assembly.h"

#include <algorithm>
#include <array>
#include <atomic>

#include <Eigen/Dense>

namespace dynsolid::solid {


namespace {

using SparseMatrix = subdivision::SparseMatrix;

struct Cell {
  std::vector<std::pair<int, int32_t>> elements;  // (kind, index in block), block order
  std::vector<int32_t> support;                   // ascending control points
  Key128 key;
};

}  // namespace

void GatherCellRows(const SparseMatrix& nm, const int32_t* ids, int n,
                    const std::vector<int32_t>& column, std::vector<int32_t>& mark,
                    ElementRows& out) {
  // The cell columns touched, in ascending order (a scan of the cell's few
  // columns, no sort), then each one's place among them.
  int32_t end = 0;
  for (int i = 0; i < n; ++i) {
    for (SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
      const int32_t col = column[it.col()];
      mark[col] = 0;
      end = std::max(end, col + 1);
    }
  }
  out.support.clear();
  for (int32_t col = 0; col < end; ++col) {
    if (mark[col] < 0) continue;
    mark[col] = static_cast<int32_t>(out.support.size());
    out.support.push_back(col);
  }
  out.b.setZero(n, static_cast<Eigen::Index>(out.support.size()));
  for (int i = 0; i < n; ++i) {
    for (SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
      out.b(i, mark[column[it.col()]]) = it.value();
    }
  }
  for (int32_t col : out.support) mark[col] = -1;
}

namespace {

// Per thread: scratch marks and node rows' hashes in the current cell.
struct Scratch {
  std::vector<int32_t> cell_mark;
  std::vector<int32_t> node_stamp;  // the cell whose numbering node_key[i] is in
  std::vector<Key128> node_key;
};

// job(thread, part) once for every part in [0, parts), each thread taking
// the next part not yet taken.
template <typename Job>
void Parts(WorkerPool& pool, int parts, Job&& job) {
  std::atomic<int> next{0};
  pool.Run([&](int t) {
    for (int k = next.fetch_add(1, std::memory_order_relaxed); k < parts;
         k = next.fetch_add(1, std::memory_order_relaxed)) {
      job(t, k);
    }
  });
}

}  // namespace

std::shared_ptr<CellPartials> SumByCell(const SparseMatrix& nm, const models::ElementLayout& layout,
                                        const std::vector<int32_t>& control_cell,
                                        int32_t control_cells, const CellSumSpec& spec,
                                        const CellPartials* previous, WorkerPool& pool, bool dense,
                                        CellSums& out) {
  const int32_t nc = static_cast<int32_t>(nm.cols());
  const int dofs = spec.dofs, outputs = spec.outputs;
  std::vector<Cell> cells(control_cells);
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t fine = block.cell[e];
      const int32_t c = control_cell.empty() ? fine : control_cell[fine];
      cells[c].elements.push_back({kind, e});
    }
  }
  // Group keys, once per group.
  std::array<std::vector<Key128>, 3> group_keys;
  for (int kind = 0; kind < 3; ++kind) {
    group_keys[kind].resize(layout.blocks[kind].groups.size());
  }
  const int threads = pool.size();
  pool.Run([&](int t) {
    for (int kind = 0; kind < 3; ++kind) {
      std::vector<Key128>& keys = group_keys[kind];
      for (size_t g = t; g < keys.size(); g += threads) keys[g] = spec.group_key(kind, static_cast<int32_t>(g));
    }
  });
  std::vector<Scratch> scratch(threads);
  for (Scratch& s : scratch) s.cell_mark.assign(nc, -1);
  // Each cell's support and geometry key (its elements' kinds and node
  // rows, the columns numbered within the cell): made here unless
  // spec.geometry has them from another sum of this build.
  CellGeometry own;
  CellGeometry& geometry = spec.geometry != nullptr ? *spec.geometry : own;
  if (static_cast<int32_t>(geometry.keys.size()) != control_cells) {
    geometry.supports.assign(control_cells, {});
    geometry.keys.assign(control_cells, {});
    for (Scratch& s : scratch) {
      s.node_stamp.assign(nm.rows(), -1);
      s.node_key.resize(nm.rows());
    }
    Parts(pool, control_cells, [&](int t, int c) {
      Scratch& s = scratch[t];
      const Cell& cell = cells[c];
      std::vector<int32_t>& support = geometry.supports[c];
      for (const auto& [kind, e] : cell.elements) {
        const models::ElementBlock& block = layout.blocks[kind];
        const int32_t* ids = block.element_nodes(e);
        for (int i = 0; i < block.nodes; ++i) {
          for (SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
            const int32_t col = static_cast<int32_t>(it.col());
            if (s.cell_mark[col] < 0) {
              s.cell_mark[col] = 0;
              support.push_back(col);
            }
          }
        }
      }
      std::sort(support.begin(), support.end());
      for (size_t a = 0; a < support.size(); ++a) s.cell_mark[support[a]] = static_cast<int32_t>(a);
      Hash128 h;
      h.Mix(support.size());
      h.Mix(cell.elements.size());
      for (const auto& [kind, e] : cell.elements) {
        const models::ElementBlock& block = layout.blocks[kind];
        h.Mix(static_cast<uint64_t>(kind));
        const int32_t* ids = block.element_nodes(e);
        for (int i = 0; i < block.nodes; ++i) {
          // The node's row, its columns numbered within the cell: hashed
          // once per cell (elements of a cell share most of their nodes).
          if (s.node_stamp[ids[i]] != c) {
            Hash128 row;
            row.Mix(static_cast<uint64_t>(nm.outerIndexPtr()[ids[i] + 1] - nm.outerIndexPtr()[ids[i]]));
            for (SparseMatrix::InnerIterator it(nm, ids[i]); it; ++it) {
              row.Mix(static_cast<uint64_t>(s.cell_mark[it.col()]));
              row.Double(it.value());
            }
            s.node_key[ids[i]] = row.value();
            s.node_stamp[ids[i]] = c;
          }
          h.Key(s.node_key[ids[i]]);
        }
      }
      geometry.keys[c] = h.value();
      for (int32_t col : support) s.cell_mark[col] = -1;
    });
  }
  // The cell's key: what the spec sums, its geometry, and its elements'
  // group keys.
  for (int32_t c = 0; c < control_cells; ++c) {
    Cell& cell = cells[c];
    cell.support = geometry.supports[c];
    Hash128 h;
    h.Mix(spec.salt);
    h.Mix(static_cast<uint64_t>(dofs));
    h.Mix(static_cast<uint64_t>(outputs));
    h.Key(geometry.keys[c]);
    for (const auto& [kind, e] : cell.elements) {
      h.Key(group_keys[kind][layout.blocks[kind].group[e]]);
    }
    cell.key = h.value();
  }

  // Partials: carried, shared with an earlier cell of this build, or made.
  auto next = std::make_shared<CellPartials>();
  std::vector<std::shared_ptr<const std::vector<Eigen::MatrixXd>>> partial(control_cells);
  std::vector<int32_t> to_make;
  double bytes = 0;
  for (int32_t c = 0; c < control_cells; ++c) {
    auto [it, fresh] = next->by_key.try_emplace(cells[c].key);
    if (fresh) {
      if (previous != nullptr) {
        auto p = previous->by_key.find(cells[c].key);
        if (p != previous->by_key.end()) it->second = p->second;
      }
      if (it->second == nullptr) to_make.push_back(c);
      const double side = static_cast<double>(dofs) * cells[c].support.size();
      bytes += outputs * side * side * 8.0;
    }
  }
  std::vector<std::shared_ptr<std::vector<Eigen::MatrixXd>>> made(to_make.size());
  Parts(pool, static_cast<int>(to_make.size()), [&](int t, int k) {
    const Cell& cell = cells[to_make[k]];
    const int side = dofs * static_cast<int>(cell.support.size());
    auto p = std::make_shared<std::vector<Eigen::MatrixXd>>(outputs, Eigen::MatrixXd::Zero(side, side));
    spec.make_cell(t, cell.support, cell.elements, *p);
    made[k] = std::move(p);
  });
  for (size_t k = 0; k < to_make.size(); ++k) next->by_key[cells[to_make[k]].key] = made[k];
  for (int32_t c = 0; c < control_cells; ++c) partial[c] = next->by_key[cells[c].key];

  next->made = static_cast<int32_t>(to_make.size());
  next->bytes = bytes;
  out.supports.clear();
  out.partials.clear();
  if (spec.per_cell) {
    out.matrices.clear();
    out.triplets.clear();
    out.supports.reserve(control_cells);
    for (int32_t c = 0; c < control_cells; ++c) out.supports.push_back(std::move(cells[c].support));
    out.partials = std::move(partial);
    return next;
  }
  // The sums, in cell order.
  const int64_t n = static_cast<int64_t>(dofs) * nc;
  out.matrices.clear();
  out.triplets.assign(outputs, {});
  if (dense) out.matrices.assign(outputs, Eigen::MatrixXd::Zero(n, n));
  for (int32_t c = 0; c < control_cells; ++c) {
    const std::vector<int32_t>& support = cells[c].support;
    const int side = dofs * static_cast<int>(support.size());
    for (int o = 0; o < outputs; ++o) {
      const Eigen::MatrixXd& p = (*partial[c])[o];
      for (int j = 0; j < side; ++j) {
        const int64_t col = static_cast<int64_t>(dofs) * support[j / dofs] + j % dofs;
        for (int i = 0; i < side; ++i) {
          const int64_t row = static_cast<int64_t>(dofs) * support[i / dofs] + i % dofs;
          if (dense) {
            out.matrices[o](row, col) += p(i, j);
          } else if (p(i, j) != 0) {
            out.triplets[o].emplace_back(static_cast<int32_t>(row), static_cast<int32_t>(col), p(i, j));
          }
        }
      }
    }
  }
  return next;
}

}  // namespace dynsolid::solid
