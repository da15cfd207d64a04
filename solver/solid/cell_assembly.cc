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
};

// Node row r of nm, its columns numbered by `column`: its length, then
// entry k's column and value mixed into lane k mod 4 (four independent
// chains of multiplies instead of one), the lanes folded at the end.
Key128 RowKey(const SparseMatrix& nm, int32_t r, const std::vector<int32_t>& column) {
  const int32_t begin = nm.outerIndexPtr()[r], end = nm.outerIndexPtr()[r + 1];
  const int32_t* cols = nm.innerIndexPtr();
  const double* values = nm.valuePtr();
  Hash128 lane[4];
  int32_t k = begin;
  for (; k + 4 <= end; k += 4) {
    for (int l = 0; l < 4; ++l) {
      lane[l].Mix(static_cast<uint64_t>(column[cols[k + l]]));
      lane[l].Double(values[k + l]);
    }
  }
  for (; k < end; ++k) {
    lane[(k - begin) & 3].Mix(static_cast<uint64_t>(column[cols[k]]));
    lane[(k - begin) & 3].Double(values[k]);
  }
  Hash128 h;
  h.Mix(static_cast<uint64_t>(end - begin));
  for (const Hash128& l : lane) h.Key(l.value());
  return h.value();
}

// Per thread: scratch marks and node rows' hashes in the current cell.
struct Scratch {
  std::vector<int32_t> cell_mark;
  std::vector<int32_t> node_stamp;  // the cell whose numbering node_key[i] is in
  std::vector<Key128> node_key;
  std::vector<int32_t> nodes;       // the current cell's distinct nodes
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
  std::vector<CellSumJob> jobs(1);
  jobs[0].spec = &spec;
  jobs[0].previous = previous;
  jobs[0].dense = dense;
  jobs[0].out = &out;
  SumByCells(nm, layout, control_cell, control_cells, jobs, pool);
  return std::move(jobs[0].made);
}

namespace {

// A control cell's elements and support (Cell) for every cell.
std::vector<Cell> CellsOf(const models::ElementLayout& layout,
                          const std::vector<int32_t>& control_cell, int32_t control_cells) {
  std::vector<Cell> cells(control_cells);
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t fine = block.cell[e];
      const int32_t c = control_cell.empty() ? fine : control_cell[fine];
      cells[c].elements.push_back({kind, e});
    }
  }
  return cells;
}

// Each cell's support and geometry key (its elements' kinds and node rows,
// the columns numbered within the cell) into `geometry`, unless it has
// them already (from another sum of this build).
void MakeGeometry(const SparseMatrix& nm, const models::ElementLayout& layout,
                  const std::vector<Cell>& cells, int32_t control_cells,
                  std::vector<Scratch>& scratch, WorkerPool& pool, CellGeometry& geometry) {
  if (static_cast<int32_t>(geometry.keys.size()) == control_cells) return;
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
    // The cell's distinct nodes (elements of a cell share most of
    // theirs), each row read once for the support.
    s.nodes.clear();
    for (const auto& [kind, e] : cell.elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < block.nodes; ++i) {
        if (s.node_stamp[ids[i]] == c) continue;
        s.node_stamp[ids[i]] = c;
        s.nodes.push_back(ids[i]);
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
    // Each node's row, its columns numbered within the cell.
    for (int32_t node : s.nodes) s.node_key[node] = RowKey(nm, node, s.cell_mark);
    // Four independent lanes of the elements' node rows, by node slot
    // (as RowKey): a single hash chain of a cell's thousands of node
    // keys waited on its multiplies.
    Hash128 lane[4];
    for (const auto& [kind, e] : cell.elements) {
      const models::ElementBlock& block = layout.blocks[kind];
      lane[0].Mix(static_cast<uint64_t>(kind));
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < block.nodes; ++i) lane[i & 3].Key(s.node_key[ids[i]]);
    }
    Hash128 h;
    h.Mix(support.size());
    h.Mix(cell.elements.size());
    for (const Hash128& l : lane) h.Key(l.value());
    geometry.keys[c] = h.value();
    for (int32_t col : support) s.cell_mark[col] = -1;
  });
}

// Per job: its cells' keys (what the spec sums, the cell's geometry and
// its elements' group keys) and the partials it must make (neither carried
// nor shared with an earlier cell of this build); each job's `made` started
// with the partials it takes over.
void KeyJobs(const models::ElementLayout& layout, const std::vector<Cell>& cells,
             int32_t control_cells, const CellGeometry& geometry, std::vector<CellSumJob>& jobs,
             WorkerPool& pool, std::vector<std::vector<Key128>>& keys,
             std::vector<std::vector<uint8_t>>& makes) {
  const int threads = pool.size();
  const int nj = static_cast<int>(jobs.size());
  keys.assign(nj, std::vector<Key128>(control_cells));
  makes.assign(nj, std::vector<uint8_t>(control_cells, 0));
  for (int j = 0; j < nj; ++j) {
    CellSumJob& job = jobs[j];
    const CellSumSpec& spec = *job.spec;
    std::array<std::vector<Key128>, fem::kElementKinds> group_keys;
    for (int kind = 0; kind < fem::kElementKinds; ++kind) group_keys[kind].resize(layout.blocks[kind].groups.size());
    pool.Run([&](int t) {
      for (int kind = 0; kind < fem::kElementKinds; ++kind) {
        std::vector<Key128>& gk = group_keys[kind];
        for (size_t g = t; g < gk.size(); g += threads) gk[g] = spec.group_key(kind, static_cast<int32_t>(g));
      }
    });
    job.made = std::make_shared<CellPartials>();
    CellPartials& next = *job.made;
    double bytes = 0;
    for (int32_t c = 0; c < control_cells; ++c) {
      const Cell& cell = cells[c];
      Hash128 h;
      h.Mix(spec.salt);
      h.Mix(static_cast<uint64_t>(spec.dofs));
      h.Mix(static_cast<uint64_t>(spec.outputs));
      h.Key(geometry.keys[c]);
      for (const auto& [kind, e] : cell.elements) h.Key(group_keys[kind][layout.blocks[kind].group[e]]);
      keys[j][c] = h.value();
      auto [it, fresh] = next.by_key.try_emplace(keys[j][c]);
      if (!fresh) continue;
      if (job.previous != nullptr) {
        auto p = job.previous->by_key.find(keys[j][c]);
        if (p != job.previous->by_key.end()) it->second = p->second;
      }
      if (it->second == nullptr) makes[j][c] = 1;
      const double side = static_cast<double>(spec.dofs) * cell.support.size();
      bytes += spec.outputs * side * side * 8.0;
    }
    next.bytes = bytes;
  }
}

// The partials the jobs must make, in one pass over the cells (with the
// caller's jobs `beside` first): made[j][c].
std::vector<std::vector<std::shared_ptr<std::vector<Eigen::MatrixXd>>>> MakePartials(
    const models::ElementLayout& layout, const std::vector<Cell>& cells, int32_t control_cells,
    const std::vector<CellSumJob>& jobs, const std::vector<std::vector<uint8_t>>& makes,
    WorkerPool& pool, const std::vector<std::function<void()>>& beside) {
  const int nj = static_cast<int>(jobs.size());
  // A cell's partials of every job one after another on one thread.
  std::vector<int32_t> to_make;
  for (int32_t c = 0; c < control_cells; ++c) {
    for (int j = 0; j < nj; ++j) {
      if (makes[j][c]) {
        to_make.push_back(c);
        break;
      }
    }
  }
  // Costliest first (points times support squared: the Gram products), so
  // that no thread is left with a large cell while the others are done.
  // Each partial is the same whichever thread makes it, and when.
  std::vector<double> cost(control_cells, 0);
  for (int32_t c : to_make) {
    double points = 0;
    for (const auto& [kind, e] : cells[c].elements) points += layout.tables[kind].points;
    const double side = static_cast<double>(cells[c].support.size());
    cost[c] = points * side * side;
  }
  std::stable_sort(to_make.begin(), to_make.end(),
                   [&](int32_t a, int32_t b) { return cost[a] > cost[b]; });
  std::vector<std::vector<std::shared_ptr<std::vector<Eigen::MatrixXd>>>> made(
      nj, std::vector<std::shared_ptr<std::vector<Eigen::MatrixXd>>>(control_cells));
  // The first parts are the caller's jobs beside.
  const int first = static_cast<int>(beside.size());
  Parts(pool, static_cast<int>(to_make.size()) + first, [&](int t, int part) {
    if (part < first) {
      beside[part]();
      return;
    }
    const int32_t c = to_make[part - first];
    const Cell& cell = cells[c];
    for (int j = 0; j < nj; ++j) {
      if (!makes[j][c]) continue;
      const CellSumSpec& spec = *jobs[j].spec;
      const int side = spec.dofs * static_cast<int>(cell.support.size());
      // Sized, not cleared nor copied from a prototype: make_cell writes
      // every entry (cell_assembly.h).
      auto p = std::make_shared<std::vector<Eigen::MatrixXd>>(spec.outputs);
      for (Eigen::MatrixXd& m : *p) m.resize(side, side);
      spec.make_cell(t, cell.support, cell.elements, *p);
      made[j][c] = std::move(p);
    }
  });
  return made;
}

// The control points each control point shares a cell with: point i's
// neighbours (ascending) at neighbours[first[i] .. first[i + 1]), and its
// cells (ascending) at cells_of[cell_first[i] .. cell_first[i + 1]).
struct SparsePattern {
  std::vector<int64_t> first;
  std::vector<int32_t> neighbours;
  std::vector<int32_t> cell_first;
  std::vector<int32_t> cells_of;
};

SparsePattern PatternOf(const std::vector<Cell>& cells, int32_t control_cells, int32_t nc,
                        WorkerPool& pool) {
  SparsePattern p;
  // The cells of each point, ascending.
  std::vector<int32_t>& count = p.cell_first;
  count.assign(static_cast<size_t>(nc) + 1, 0);
  for (int32_t c = 0; c < control_cells; ++c) {
    for (int32_t i : cells[c].support) ++count[i + 1];
  }
  for (int32_t i = 0; i < nc; ++i) count[i + 1] += count[i];
  p.cells_of.resize(static_cast<size_t>(count[nc]));
  {
    std::vector<int32_t> at(count.begin(), count.end() - 1);
    for (int32_t c = 0; c < control_cells; ++c) {
      for (int32_t i : cells[c].support) p.cells_of[at[i]++] = c;
    }
  }
  // Each point's neighbours: the union of its cells' supports.
  std::vector<std::vector<int32_t>> lists(nc);
  const int threads = pool.size();
  pool.RunParts(threads, [&](int t) {
    std::vector<int32_t> stamp(nc, -1);
    const int32_t lo = static_cast<int32_t>(int64_t{nc} * t / threads);
    const int32_t hi = static_cast<int32_t>(int64_t{nc} * (t + 1) / threads);
    for (int32_t i = lo; i < hi; ++i) {
      std::vector<int32_t>& list = lists[i];
      for (int32_t k = count[i]; k < count[i + 1]; ++k) {
        for (int32_t j : cells[p.cells_of[k]].support) {
          if (stamp[j] == i) continue;
          stamp[j] = i;
          list.push_back(j);
        }
      }
      std::sort(list.begin(), list.end());
    }
  });
  p.first.assign(static_cast<size_t>(nc) + 1, 0);
  for (int32_t i = 0; i < nc; ++i) p.first[i + 1] = p.first[i] + static_cast<int64_t>(lists[i].size());
  p.neighbours.reserve(static_cast<size_t>(p.first[nc]));
  for (std::vector<int32_t>& list : lists) {
    p.neighbours.insert(p.neighbours.end(), list.begin(), list.end());
    std::vector<int32_t>().swap(list);
  }
  return p;
}

// Output `o` of the partials summed in cell order straight into a row-major
// sparse matrix (dofs rows and columns per control point, 3 i + c). An
// entry is kept where some cell's partial is non-zero (a sum that cancels
// to zero stays, as an explicit zero), and each is summed from zero in
// cell order: the bits and pattern Eigen's setFromTriplets gives the
// partials' non-zero entries listed in cell order. Point by point: a
// point's rows take its cells in ascending order (so each entry's terms
// come in cell order) into a dense row buffer over its neighbours; the
// points are split between the pool's threads and their rows joined in
// point order.
SparseMatrix SumSparse(
    const std::vector<Cell>& cells, const SparsePattern& pattern, int dofs,
    const std::vector<std::shared_ptr<const std::vector<Eigen::MatrixXd>>>& partial, int o,
    WorkerPool& pool) {
  const int32_t nc = static_cast<int32_t>(pattern.first.size()) - 1;
  const int d = dofs;
  const int threads = pool.size();
  struct Rows {
    std::vector<int32_t> length;  // entries of each of the part's rows
    std::vector<int32_t> inner;
    std::vector<double> values;
  };
  std::vector<Rows> parts(threads);
  pool.RunParts(threads, [&](int t) {
    const int32_t lo = static_cast<int32_t>(int64_t{nc} * t / threads);
    const int32_t hi = static_cast<int32_t>(int64_t{nc} * (t + 1) / threads);
    Rows& out = parts[t];
    out.length.reserve(static_cast<size_t>(d) * (hi - lo));
    std::vector<int32_t> place(nc, 0);  // a neighbour's place among point i's
    std::vector<double> sum;
    std::vector<uint8_t> kept;
    for (int32_t i = lo; i < hi; ++i) {
      const int64_t width = pattern.first[i + 1] - pattern.first[i];
      const int32_t* nb = pattern.neighbours.data() + pattern.first[i];
      for (int64_t q = 0; q < width; ++q) place[nb[q]] = static_cast<int32_t>(q);
      const int64_t row_size = d * width;  // entries of one of point i's rows
      sum.assign(static_cast<size_t>(d * row_size), 0.0);
      kept.assign(static_cast<size_t>(d * row_size), 0);
      for (int32_t k = pattern.cell_first[i]; k < pattern.cell_first[i + 1]; ++k) {
        const int32_t c = pattern.cells_of[k];
        const std::vector<int32_t>& support = cells[c].support;
        const int s = static_cast<int>(support.size());
        const int ki = static_cast<int>(std::lower_bound(support.begin(), support.end(), i) -
                                        support.begin());
        const Eigen::MatrixXd& p = (*partial[c])[o];
        for (int jj = 0; jj < s; ++jj) {
          const int64_t at = static_cast<int64_t>(d) * place[support[jj]];
          for (int b = 0; b < d; ++b) {
            const double* column = p.data() + static_cast<int64_t>(d * jj + b) * p.rows();
            for (int a = 0; a < d; ++a) {
              const double v = column[d * ki + a];
              if (v == 0) continue;
              const int64_t e = a * row_size + at + b;
              sum[e] += v;
              kept[e] = 1;
            }
          }
        }
      }
      for (int a = 0; a < d; ++a) {
        int32_t n = 0;
        for (int64_t q = 0; q < row_size; ++q) {
          if (!kept[a * row_size + q]) continue;
          out.inner.push_back(static_cast<int32_t>(d * nb[q / d] + q % d));
          out.values.push_back(sum[a * row_size + q]);
          ++n;
        }
        out.length.push_back(n);
      }
    }
  });
  // The parts' rows, in point order, straight into the matrix's arrays.
  size_t nnz = 0;
  for (const Rows& r : parts) nnz += r.inner.size();
  SparseMatrix m(static_cast<int32_t>(d) * nc, static_cast<int32_t>(d) * nc);
  m.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int32_t* outer = m.outerIndexPtr();
  outer[0] = 0;
  int64_t row = 0;
  size_t at = 0;
  for (Rows& r : parts) {
    for (int32_t n : r.length) {
      outer[row + 1] = outer[row] + n;
      ++row;
    }
    std::copy(r.inner.begin(), r.inner.end(), m.innerIndexPtr() + at);
    std::copy(r.values.begin(), r.values.end(), m.valuePtr() + at);
    at += r.inner.size();
    r = Rows();
  }
  return m;
}

// Each job's partials installed in its `made`, and its sums: per cell
// (spec.per_cell) or summed in cell order into dense matrices or sparse ones.
void FinishJobs(const std::vector<Cell>& cells, int32_t control_cells, int32_t nc,
                std::vector<CellSumJob>& jobs, const std::vector<std::vector<Key128>>& keys,
                const std::vector<std::vector<uint8_t>>& makes,
                std::vector<std::vector<std::shared_ptr<std::vector<Eigen::MatrixXd>>>>& made,
                WorkerPool& pool) {
  const int nj = static_cast<int>(jobs.size());
  for (int j = 0; j < nj; ++j) {
    CellSumJob& job = jobs[j];
    const CellSumSpec& spec = *job.spec;
    CellPartials& next = *job.made;
    int32_t count = 0;
    for (int32_t c = 0; c < control_cells; ++c) {
      if (!makes[j][c]) continue;
      next.by_key[keys[j][c]] = std::move(made[j][c]);
      ++count;
    }
    next.made = count;
    std::vector<std::shared_ptr<const std::vector<Eigen::MatrixXd>>> partial(control_cells);
    for (int32_t c = 0; c < control_cells; ++c) partial[c] = next.by_key[keys[j][c]];
    CellSums& out = *job.out;
    out.supports.clear();
    out.partials.clear();
    if (spec.per_cell) {
      out.matrices.clear();
      out.sparse.clear();
      out.supports.reserve(control_cells);
      for (int32_t c = 0; c < control_cells; ++c) out.supports.push_back(cells[c].support);
      out.partials = std::move(partial);
      continue;
    }
    // The sums, in cell order.
    const int dofs = spec.dofs, outputs = spec.outputs;
    const int64_t n = static_cast<int64_t>(dofs) * nc;
    out.matrices.clear();
    out.sparse.assign(outputs, {});
    if (!job.dense) {
      const SparsePattern pattern = PatternOf(cells, control_cells, nc, pool);
      for (int o = 0; o < outputs; ++o) {
        out.sparse[o] = SumSparse(cells, pattern, dofs, partial, o, pool);
      }
      continue;
    }
    out.matrices.resize(outputs);
    // Each output on a pool thread of its own (Mt and Dt), its cells in order.
    pool.RunParts(outputs, [&](int o) {
      out.matrices[o].setZero(n, n);
      for (int32_t c = 0; c < control_cells; ++c) {
        const std::vector<int32_t>& support = cells[c].support;
        const int side = dofs * static_cast<int>(support.size());
        const Eigen::MatrixXd& p = (*partial[c])[o];
        for (int jj = 0; jj < side; ++jj) {
          const int64_t col = static_cast<int64_t>(dofs) * support[jj / dofs] + jj % dofs;
          for (int i = 0; i < side; ++i) {
            const int64_t row = static_cast<int64_t>(dofs) * support[i / dofs] + i % dofs;
            out.matrices[o](row, col) += p(i, jj);
          }
        }
      }
    });
  }
}

}  // namespace

void SumByCells(const SparseMatrix& nm, const models::ElementLayout& layout,
                const std::vector<int32_t>& control_cell, int32_t control_cells,
                std::vector<CellSumJob>& jobs, WorkerPool& pool,
                const std::vector<std::function<void()>>& beside) {
  const int32_t nc = static_cast<int32_t>(nm.cols());
  std::vector<Cell> cells = CellsOf(layout, control_cell, control_cells);
  const int threads = pool.size();
  std::vector<Scratch> scratch(threads);
  for (Scratch& s : scratch) s.cell_mark.assign(nc, -1);
  // The cells' supports and geometry keys: made here unless a job's
  // spec.geometry has them from another sum of this build.
  CellGeometry own;
  CellGeometry* shared = nullptr;
  for (const CellSumJob& job : jobs) {
    if (job.spec->geometry != nullptr) shared = job.spec->geometry;
  }
  CellGeometry& geometry = shared != nullptr ? *shared : own;
  MakeGeometry(nm, layout, cells, control_cells, scratch, pool, geometry);
  for (int32_t c = 0; c < control_cells; ++c) cells[c].support = geometry.supports[c];
  std::vector<std::vector<Key128>> keys;
  std::vector<std::vector<uint8_t>> makes;
  KeyJobs(layout, cells, control_cells, geometry, jobs, pool, keys, makes);
  auto made = MakePartials(layout, cells, control_cells, jobs, makes, pool, beside);
  FinishJobs(cells, control_cells, nc, jobs, keys, makes, made, pool);
}

}  // namespace dynsolid::solid
