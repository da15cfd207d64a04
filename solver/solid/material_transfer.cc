#include "solver/solid/material_transfer.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace dynsolid::solid {

// The material samples of one old control cell, binned on a uniform grid
// for nearest-sample queries.
class CellSamples {
 public:
  void Add(const Eigen::Vector3d& x, const models::MaterialPoint& m) {
    xs_.push_back(x);
    ms_.push_back(m);
  }
  void Index() {
    if (xs_.empty()) return;
    lo_ = hi_ = xs_[0];
    for (const Eigen::Vector3d& x : xs_) {
      lo_ = lo_.cwiseMin(x);
      hi_ = hi_.cwiseMax(x);
    }
    const double extent = std::max((hi_ - lo_).maxCoeff(), 1e-12);
    n_ = std::clamp(static_cast<int>(std::cbrt(static_cast<double>(xs_.size()))), 1, 64);
    bin_ = extent / n_ * (1 + 1e-9);
    bins_.assign(static_cast<size_t>(n_) * n_ * n_, {});
    for (size_t k = 0; k < xs_.size(); ++k) bins_[Bin(Cell(xs_[k]))].push_back(static_cast<int32_t>(k));
  }
  // The material of the sample nearest x (ties: the lowest index).
  const models::MaterialPoint& Nearest(const Eigen::Vector3d& x) const {
    const Eigen::Vector3i c = Cell(x);
    double best = std::numeric_limits<double>::infinity();
    int32_t best_k = 0;
    for (int r = 0; r <= n_; ++r) {
      // Every sample in rings beyond r is at least (r - 1) bins away... stop
      // once the best is closer than the ring's inner distance.
      if (best_k >= 0 && std::isfinite(best) && (r - 1) * bin_ > std::sqrt(best)) break;
      for (int i = c.x() - r; i <= c.x() + r; ++i) {
        for (int j = c.y() - r; j <= c.y() + r; ++j) {
          for (int k = c.z() - r; k <= c.z() + r; ++k) {
            if (std::max({std::abs(i - c.x()), std::abs(j - c.y()), std::abs(k - c.z())}) != r) continue;
            if (i < 0 || j < 0 || k < 0 || i >= n_ || j >= n_ || k >= n_) continue;
            for (int32_t s : bins_[Bin({i, j, k})]) {
              const double d = (xs_[s] - x).squaredNorm();
              if (d < best || (d == best && s < best_k)) {
                best = d;
                best_k = s;
              }
            }
          }
        }
      }
    }
    return ms_[best_k];
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& x) const {
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a) {
      c[a] = std::clamp(static_cast<int>(std::floor((x[a] - lo_[a]) / bin_)), 0, n_ - 1);
    }
    return c;
  }
  size_t Bin(const Eigen::Vector3i& c) const {
    return (static_cast<size_t>(c.z()) * n_ + c.y()) * n_ + c.x();
  }
  std::vector<Eigen::Vector3d> xs_;
  std::vector<models::MaterialPoint> ms_;
  Eigen::Vector3d lo_, hi_;
  int n_ = 1;
  double bin_ = 1;
  std::vector<std::vector<int32_t>> bins_;
};

namespace {

// The key of an element's rest nodes: kind, then node row(i) for i < n.
template <typename Row>
Key128 NodesKey(int kind, int n, const Row& row) {
  Hash128 h;
  h.Mix(static_cast<uint64_t>(kind));
  for (int i = 0; i < n; ++i) h.Doubles(row(i), 3);
  return h.value();
}

}  // namespace

MaterialTransfer::MaterialTransfer(const models::ElementLayout& layout, const Points& old_nodes,
                                   const Points& rest_nodes,
                                   const std::vector<int32_t>& control_cell, int32_t old_cells,
                                   const std::vector<int32_t>& cell_source,
                                   models::MaterialPoint base)
    : layout_(layout), old_nodes_(old_nodes), rest_nodes_(rest_nodes),
      control_cell_(control_cell), cell_source_(cell_source), base_(base),
      old_elements_(old_cells) {
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = layout_.blocks[kind];
    for (int32_t e = 0; e < block.size(); ++e) {
      old_elements_[control_cell_[block.cell[e]]].push_back({kind, e});
    }
  }
  by_cell_.resize(old_cells);
  binned_ = std::make_unique<std::once_flag[]>(old_cells);
  uniform_arrays_.resize(old_cells);
  std::vector<uint8_t> named(old_cells, 0);
  for (int32_t src : cell_source) {
    if (src >= 0) named[src] = 1;
  }
  // Per material array: every sample equal to its first (arrays are
  // distinct by content, so a cell is of one material when its elements'
  // arrays are each of one and those agree).
  std::vector<uint8_t> constant(layout_.materials.size(), 0);
  for (size_t m = 0; m < layout_.materials.size(); ++m) {
    const std::vector<models::MaterialPoint>& a = layout_.materials[m];
    constant[m] = !a.empty() && std::all_of(a.begin(), a.end(),
                                            [&](const models::MaterialPoint& p) { return p == a[0]; });
  }
  for (int32_t src = 0; src < old_cells; ++src) {
    if (!named[src] || old_elements_[src].empty()) continue;
    const models::MaterialPoint* first = nullptr;
    bool same = true;
    for (const auto& [k, e] : old_elements_[src]) {
      const models::ElementBlock& block = layout_.blocks[k];
      const int32_t m = block.groups[block.group[e]].material;
      if (!constant[m]) {
        same = false;
        break;
      }
      if (first == nullptr) first = &layout_.materials[m][0];
      if (!(layout_.materials[m][0] == *first)) {
        same = false;
        break;
      }
    }
    if (same && first != nullptr) {
      for (int kind = 0; kind < fem::kElementKinds; ++kind) {
        uniform_arrays_[src][kind].assign(layout_.tables[kind].points, *first);
      }
      continue;
    }
    // Its elements keyed by their rest nodes.
    for (const auto& [k, e] : old_elements_[src]) {
      const int32_t* ids = layout_.blocks[k].element_nodes(e);
      by_nodes_.try_emplace(NodesKey(k, layout_.blocks[k].nodes,
                                     [&](int i) { return old_nodes_.row(ids[i]).data(); }),
                           k, e);
    }
  }
}

MaterialTransfer::~MaterialTransfer() = default;

models::MaterialPoint MaterialTransfer::Sample(const Eigen::Vector3d& x, int32_t cell) {
  const int32_t src = cell_source_[cell];
  if (src < 0 || old_elements_[src].empty()) return base_;
  std::call_once(binned_[src], [&] {
    for (const auto& [k, e] : old_elements_[src]) {
      const models::ElementBlock& block = layout_.blocks[k];
      const fem::KindTable& table = layout_.tables[k];
      const int32_t* ids = block.element_nodes(e);
      const std::vector<models::MaterialPoint>& array =
          layout_.materials[block.groups[block.group[e]].material];
      for (int q = 0; q < table.points; ++q) {
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        for (int i = 0; i < block.nodes; ++i) {
          p += table.N(q)[i] * old_nodes_.row(ids[i]).transpose();
        }
        by_cell_[src].Add(p, array[q]);
      }
    }
    by_cell_[src].Index();
  });
  return by_cell_[src].Nearest(x);
}

const std::vector<models::MaterialPoint>* MaterialTransfer::Whole(int kind,
                                                                  const fem::NodeMatrixX3& x,
                                                                  int32_t cell) const {
  const int32_t src = cell_source_[cell];
  if (src < 0 || old_elements_[src].empty()) return nullptr;
  if (!uniform_arrays_[src][kind].empty()) return &uniform_arrays_[src][kind];
  auto it = by_nodes_.find(NodesKey(kind, static_cast<int>(x.rows()),
                                    [&](int i) { return x.row(i).data(); }));
  if (it == by_nodes_.end()) return nullptr;
  const auto [k, e] = it->second;
  const models::ElementBlock& block = layout_.blocks[k];
  if (control_cell_[block.cell[e]] != cell_source_[cell]) return nullptr;
  const int32_t* ids = block.element_nodes(e);
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (x.row(i) != rest_nodes_.row(ids[i])) return nullptr;
  }
  return &layout_.materials[block.groups[block.group[e]].material];
}

}  // namespace dynsolid::solid
