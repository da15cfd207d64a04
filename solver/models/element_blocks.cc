#include "solver/models/element_blocks.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <numeric>
#include <unordered_map>

#include <Eigen/LU>

#include "solver/common/hash128.h"
#include "solver/common/worker_pool.h"
#include "solver/fem/cubic_tensor.h"

namespace dynsolid::models {
namespace {

const std::vector<int32_t>& NodesOfKind(const fem::ElementSet& e, int kind) {
  return kind == 0 ? e.cubic_nodes : kind == 1 ? e.linear_nodes : e.pyramid_nodes;
}
const std::vector<int32_t>& CellsOfKind(const fem::ElementSet& e, int kind) {
  return kind == 0 ? e.cubic_cell : kind == 1 ? e.linear_cell : e.pyramid_cell;
}

// Bits 3 k, 3 k + 1, 3 k + 2 of the result are bit k of x, y, z (k < 21).
uint64_t Interleave3(uint32_t x, uint32_t y, uint32_t z) {
  auto spread = [](uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  return spread(x) | spread(y) << 1 | spread(z) << 2;
}

// Per element of `block`, the Z-order (Morton) key of its centre (the
// mean of its rest nodes) on a grid of the smallest cell size. On a
// regular grid each element's cell is one grid point and 64 consecutive
// keys a 4 x 4 x 4 cube of cells, whatever order the mesh numbers its
// cells in: batches of consecutive elements of a group are then compact
// clusters, which touch the fewest nodes.
std::vector<uint64_t> ZOrderKeys(const ElementBlock& block, const Points& rest) {
  const int32_t count = block.size();
  const int n = block.nodes;
  std::vector<uint64_t> key(count, 0);
  if (count == 0) return key;
  Points centre(count, 3);
  double smallest = std::numeric_limits<double>::infinity();
  for (int32_t e = 0; e < count; ++e) {
    const int32_t* ids = block.element_nodes(e);
    Eigen::RowVector3d lo = rest.row(ids[0]), hi = lo, sum = Eigen::RowVector3d::Zero();
    for (int i = 0; i < n; ++i) {
      lo = lo.cwiseMin(rest.row(ids[i]));
      hi = hi.cwiseMax(rest.row(ids[i]));
      sum += rest.row(ids[i]);
    }
    centre.row(e) = sum / n;
    const double extent = (hi - lo).maxCoeff();
    if (extent > 0) smallest = std::min(smallest, extent);
  }
  const Eigen::RowVector3d lo = centre.colwise().minCoeff();
  const double span = (centre.colwise().maxCoeff() - lo).maxCoeff();
  constexpr double kLevels = (1 << 21) - 1;
  // A cubic element's nodes span three cells, a linear or pyramid's one.
  const double stencil = block.kind == fem::ElementKind::kCubic ? 3 : 1;
  const double step =
      std::max(std::isfinite(smallest) ? smallest / stencil : 1.0, span / kLevels);
  if (!(step > 0)) return key;
  for (int32_t e = 0; e < count; ++e) {
    uint32_t q[3];
    for (int c = 0; c < 3; ++c) {
      const double t = std::clamp(std::floor((centre(e, c) - lo[c]) / step + 0.5), 0.0, kLevels);
      q[c] = static_cast<uint32_t>(t);
    }
    key[e] = Interleave3(q[0], q[1], q[2]);
  }
  return key;
}

// Calls fn(begin, end) over [0, n) in pool-size contiguous ranges on
// `pool` (null: at once on this thread).
template <typename Fn>
void Ranges(WorkerPool* pool, int64_t n, Fn&& fn) {
  if (pool == nullptr || pool->size() == 1 || n < 64) {
    fn(int64_t{0}, n);
    return;
  }
  const int parts = pool->size();
  pool->Run([&](int k) { fn(n * k / parts, n * (k + 1) / parts); });
}

// The linear hexahedron's node a sits at parametric corner kCorner[a]
// (fem/shape.cc); a cubic element's node 16 i + 4 j + k at tensor index
// (i, j, k).
constexpr int kLinearCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                     {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

// Relabels each cubic and linear element's nodes by the rotation of its
// parametric cube (one of 24: no mirror, so det J keeps its sign) that best
// aligns its u, v, w axes with x, y, z at rest. The subdivided mesh labels a
// cell's corners in whatever order its faces came in, so congruent
// elements arrive in several orientations; their node lists (and rest
// shapes up to translation) then differ, and they would fall into
// separate groups, each one element in every few. Aligned, the congruent
// elements of a regular region form one group, whose consecutive members
// are neighbours: a batch of them touches few nodes (about 350 for 64
// cubic elements of a block, against some 2000 with the orientations
// mixed) and shares one matrix. The tensor B-spline and trilinear bases
// are symmetric under the cube's rotations (N_i(1 - u) = N_{3-i}(u)) and
// symmetric Gauss rules map onto themselves, so the relabelled element is
// the same element: same shape functions at the same physical points.
void AlignElementAxes(ElementBlock& block, const Points& rest, WorkerPool* pool) {
  if (block.kind == fem::ElementKind::kPyramid) return;
  const int side = block.kind == fem::ElementKind::kCubic ? 4 : 2;
  const int n = block.nodes;
  // Node number <-> tensor index.
  std::vector<std::array<int, 3>> index(n);
  std::vector<int> number(side * side * side);
  for (int a = 0; a < n; ++a) {
    if (side == 4) {
      index[a] = {a / 16, (a / 4) % 4, a % 4};
    } else {
      index[a] = {kLinearCorner[a][0], kLinearCorner[a][1], kLinearCorner[a][2]};
    }
    number[(index[a][0] * side + index[a][1]) * side + index[a][2]] = a;
  }
  // The 24 rotations: new axis c is old axis perm[c], reversed where
  // flip[c]; proper when the permutation's sign times the flips' is +1.
  struct Rotation {
    std::array<int, 3> perm;
    std::array<bool, 3> flip;
  };
  std::vector<Rotation> rotations;
  std::array<int, 3> perm{0, 1, 2};
  do {
    const int inversions = (perm[0] > perm[1]) + (perm[0] > perm[2]) + (perm[1] > perm[2]);
    for (int f = 0; f < 8; ++f) {
      const std::array<bool, 3> flip{(f & 1) != 0, (f & 2) != 0, (f & 4) != 0};
      if ((inversions + flip[0] + flip[1] + flip[2]) % 2 == 0) rotations.push_back({perm, flip});
    }
  } while (std::next_permutation(perm.begin(), perm.end()));
  // Per rotation, new node a takes old node source[a].
  std::vector<std::vector<int>> source(rotations.size(), std::vector<int>(n));
  for (size_t r = 0; r < rotations.size(); ++r) {
    for (int a = 0; a < n; ++a) {
      std::array<int, 3> old{};
      for (int c = 0; c < 3; ++c) {
        const int t = index[a][c];
        old[rotations[r].perm[c]] = rotations[r].flip[c] ? side - 1 - t : t;
      }
      source[r][a] = number[(old[0] * side + old[1]) * side + old[2]];
    }
  }
  // Each element on its own (its own node ids written): in parallel.
  Ranges(pool, block.size(), [&](int64_t begin, int64_t end) {
    std::vector<int32_t> ids(n);
    for (int64_t e = begin; e < end; ++e) {
      int32_t* nodes = block.node_ids.data() + static_cast<size_t>(e) * n;
      // The old axes' directions: sum over nodes of (index - centre) x.
      Eigen::Matrix3d axis = Eigen::Matrix3d::Zero();  // column b: old axis b
      for (int a = 0; a < n; ++a) {
        for (int b = 0; b < 3; ++b) {
          axis.col(b) += (index[a][b] - 0.5 * (side - 1)) * rest.row(nodes[a]).transpose();
        }
      }
      size_t best = 0;
      double best_score = -std::numeric_limits<double>::infinity();
      for (size_t r = 0; r < rotations.size(); ++r) {
        double score = 0;
        for (int c = 0; c < 3; ++c) {
          const double along = axis(c, rotations[r].perm[c]);
          score += rotations[r].flip[c] ? -along : along;
        }
        if (score > best_score) best_score = score, best = r;
      }
      for (int a = 0; a < n; ++a) ids[a] = nodes[source[best][a]];
      std::copy(ids.begin(), ids.end(), nodes);
    }
  });
}

}  // namespace

int64_t PerElementBytes(const ElementLayout& layout) {
  int64_t bytes = 0, count = 0;
  for (const ElementBlock& b : layout.blocks) {
    bytes += static_cast<int64_t>(b.size()) * (b.nodes * 4 + 4 + 4 + 4 * 8);
    count += b.size();
  }
  return count > 0 ? bytes / count : 0;
}

ElementSchedule ScheduleElements(const ElementLayout& layout, int32_t batch_size, int parts,
                                 int32_t num_nodes, const PooledGroups* pooled) {
  ElementSchedule out;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const ElementBlock& block = layout.blocks[kind];
    std::vector<int32_t>& order = out.order[kind];
    order.reserve(block.by_group.size());
    std::vector<int32_t> pool;
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      const auto begin = block.by_group.begin() + block.group_start[gi];
      const auto end = block.by_group.begin() + block.group_start[gi + 1];
      if (pooled != nullptr && !(*pooled)[kind].empty() && (*pooled)[kind][gi] != 0) {
        pool.insert(pool.end(), begin, end);
        continue;
      }
      const int32_t first = static_cast<int32_t>(order.size());
      order.insert(order.end(), begin, end);
      for (int32_t s = first; s < static_cast<int32_t>(order.size()); s += batch_size) {
        out.batches.push_back({kind, static_cast<int32_t>(gi), s,
                               std::min<int32_t>(batch_size, static_cast<int32_t>(order.size()) - s)});
      }
    }
    std::sort(pool.begin(), pool.end());
    const int32_t first = static_cast<int32_t>(order.size());
    order.insert(order.end(), pool.begin(), pool.end());
    for (int32_t s = first; s < static_cast<int32_t>(order.size()); s += batch_size) {
      out.batches.push_back(
          {kind, kPooled, s, std::min<int32_t>(batch_size, static_cast<int32_t>(order.size()) - s)});
    }
  }
  // An element costs its matrix products (3 n^2 multiply-adds in either
  // model, up to a factor) plus its frame, rotations, gathers and scatters
  // (a few dozen operations per node): n^2 + 27 n, fitted to a profile of
  // block3 (a cubic element about 21 times a linear one, not 64).
  auto cost = [&](const ElementBatch& b) {
    const double n = layout.blocks[b.kind].nodes;
    return (n * n + 27 * n) * b.count;
  };
  double total = 0;
  for (const ElementBatch& b : out.batches) total += cost(b);
  out.part_start.assign(1, 0);
  double acc = 0;
  for (size_t i = 0; i < out.batches.size(); ++i) {
    acc += cost(out.batches[i]);
    while (out.part_start.size() < static_cast<size_t>(parts) &&
           acc >= total * static_cast<double>(out.part_start.size()) / parts) {
      out.part_start.push_back(i + 1);
    }
  }
  while (out.part_start.size() <= static_cast<size_t>(parts)) {
    out.part_start.push_back(out.batches.size());
  }
  out.node_parts.assign(num_nodes, 0);
  out.part_nodes.resize(parts);
  for (int k = 0; k < parts; ++k) {
    const uint8_t bit = static_cast<uint8_t>(1u << k);
    for (size_t bi = out.part_start[k]; bi < out.part_start[k + 1]; ++bi) {
      const ElementBatch& batch = out.batches[bi];
      const ElementBlock& block = layout.blocks[batch.kind];
      for (int32_t b = 0; b < batch.count; ++b) {
        const int32_t* ids = block.element_nodes(out.order[batch.kind][batch.first + b]);
        for (int i = 0; i < block.nodes; ++i) out.node_parts[ids[i]] |= bit;
      }
    }
    for (int32_t v = 0; v < num_nodes; ++v) {
      if (out.node_parts[v] & bit) out.part_nodes[k].push_back(v);
    }
  }
  return out;
}

std::vector<uint8_t> SmallGroups(const ElementBlock& block, int32_t max_members) {
  std::vector<uint8_t> small(block.groups.size(), 0);
  for (size_t gi = 0; gi < block.groups.size(); ++gi) {
    small[gi] = block.group_start[gi + 1] - block.group_start[gi] <= max_members;
  }
  return small;
}

void IndexBatchNodes(const ElementLayout& layout, ElementSchedule& schedule) {
  schedule.batch_nodes.clear();
  schedule.local_ids.clear();
  schedule.max_batch_nodes = 0;
  int32_t max_node = -1;
  for (const ElementBlock& block : layout.blocks) {
    for (int32_t id : block.node_ids) max_node = std::max(max_node, id);
  }
  // local[node]: the node's place in the current batch's sorted list (-1:
  // not in it; reset after each batch).
  std::vector<int32_t> local(static_cast<size_t>(max_node) + 1, -1);
  std::vector<int32_t> nodes;
  for (ElementBatch& batch : schedule.batches) {
    const ElementBlock& block = layout.blocks[batch.kind];
    const int n = block.nodes;
    nodes.clear();
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t* ids = block.element_nodes(schedule.order[batch.kind][batch.first + b]);
      for (int i = 0; i < n; ++i) {
        if (local[ids[i]] < 0) {
          local[ids[i]] = 0;
          nodes.push_back(ids[i]);
        }
      }
    }
    std::sort(nodes.begin(), nodes.end());
    for (size_t k = 0; k < nodes.size(); ++k) local[nodes[k]] = static_cast<int32_t>(k);
    batch.nodes_begin = static_cast<int64_t>(schedule.batch_nodes.size());
    batch.num_nodes = static_cast<int32_t>(nodes.size());
    batch.local_begin = static_cast<int64_t>(schedule.local_ids.size());
    schedule.max_batch_nodes = std::max(schedule.max_batch_nodes, batch.num_nodes);
    schedule.batch_nodes.insert(schedule.batch_nodes.end(), nodes.begin(), nodes.end());
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t* ids = block.element_nodes(schedule.order[batch.kind][batch.first + b]);
      for (int i = 0; i < n; ++i) schedule.local_ids.push_back(static_cast<uint16_t>(local[ids[i]]));
    }
    for (int32_t v : nodes) local[v] = -1;
  }
}

int64_t BatchTableBytes(const ElementLayout& layout, const ElementSchedule& schedule) {
  int64_t elements = 0;
  for (const ElementBlock& b : layout.blocks) elements += b.size();
  if (elements == 0) return 0;
  const int64_t bytes = static_cast<int64_t>(schedule.batch_nodes.size()) * 4 +
                        static_cast<int64_t>(schedule.local_ids.size()) * 2 +
                        static_cast<int64_t>(schedule.batches.size()) * sizeof(ElementBatch);
  return bytes / elements;
}

void ClearPartRows(const ElementSchedule& schedule, int k, Points& buffer) {
  double* b = buffer.data();
  for (int32_t v : schedule.part_nodes[k]) b[3 * v] = b[3 * v + 1] = b[3 * v + 2] = 0;
}

void SumPartRows(const ElementSchedule& schedule, const Points* const* buffers, int32_t begin,
                 int32_t end, Points& out) {
  double* o = out.data();
  for (int32_t v = begin; v < end; ++v) {
    double x = 0, y = 0, z = 0;
    for (uint32_t mask = schedule.node_parts[v]; mask != 0; mask &= mask - 1) {
      const double* b = buffers[__builtin_ctz(mask)]->data() + 3 * static_cast<int64_t>(v);
      x += b[0];
      y += b[1];
      z += b[2];
    }
    o[3 * v] = x;
    o[3 * v + 1] = y;
    o[3 * v + 2] = z;
  }
}

namespace {

// A group's rest shape (its rest key) and stiffness samples, hashed.
uint64_t StiffnessKey(const ElementLayout& layout, const ElementGroup& grp) {
  Hash128 h;
  h.Key(grp.rest_key);
  for (const MaterialPoint& m : layout.materials[grp.material]) {
    h.Double(m.young);
    h.Double(m.poisson);
  }
  return h.value().first;
}

bool SameStiffness(const ElementLayout& a, const ElementGroup& ga, const ElementLayout& b,
                   const ElementGroup& gb) {
  if (ga.rest.rows() != gb.rest.rows() || ga.rest != gb.rest) return false;
  const auto& ma = a.materials[ga.material];
  const auto& mb = b.materials[gb.material];
  if (ma.size() != mb.size()) return false;
  for (size_t q = 0; q < ma.size(); ++q) {
    if (ma[q].young != mb[q].young || ma[q].poisson != mb[q].poisson) return false;
  }
  return true;
}

}  // namespace

std::vector<int32_t> MatchStiffnessGroups(const ElementLayout& layout,
                                          const ElementLayout& previous, int kind) {
  const ElementBlock& block = layout.blocks[kind];
  const ElementBlock& old = previous.blocks[kind];
  std::multimap<uint64_t, int32_t> by_key;
  for (size_t g = 0; g < old.groups.size(); ++g) {
    by_key.emplace(StiffnessKey(previous, old.groups[g]), static_cast<int32_t>(g));
  }
  std::vector<int32_t> match(block.groups.size(), -1);
  for (size_t g = 0; g < block.groups.size(); ++g) {
    const auto range = by_key.equal_range(StiffnessKey(layout, block.groups[g]));
    for (auto it = range.first; it != range.second; ++it) {
      if (SameStiffness(layout, block.groups[g], previous, old.groups[it->second])) {
        match[g] = it->second;
        break;
      }
    }
  }
  return match;
}

Key128 RestKey(const fem::NodeMatrixX3& rest) {
  Hash128 h;
  h.Doubles(rest.data(), rest.size());
  return h.value();
}

namespace {

// Material sample arrays deduplicated by content (equal values, as ==
// compares them), numbered in the order they are first added
// (BuildElementLayout's order): found by a hash of their values (-0 as
// +0), then compared.
class MaterialTable {
 public:
  explicit MaterialTable(ElementLayout& layout) : layout_(layout) {}
  int32_t Add(const std::vector<MaterialPoint>& samples) {
    Hash128 h;
    h.Mix(samples.size());
    for (const MaterialPoint& m : samples) {
      for (double v : {m.young, m.poisson, m.density, m.damping}) h.Double(v + 0.0);
    }
    std::vector<int32_t>& same_key = index_[h.value()];
    for (int32_t k : same_key) {
      if (layout_.materials[k] == samples) return k;
    }
    const int32_t k = static_cast<int32_t>(layout_.materials.size());
    layout_.materials.push_back(samples);
    same_key.push_back(k);
    return k;
  }

 private:
  ElementLayout& layout_;
  std::unordered_map<Key128, std::vector<int32_t>, Key128Hash> index_;
};

// What a group keeps of its rest shape (groups of one shape share it).
struct ShapeData {
  fem::NodeMatrixX3 rest;             // the first element of the shape's rest nodes
  fem::NodeMatrixX3 centre_gradient;  // physical gradients at the centre
  double centre_det = 0;              // det J0 there
  double volume = 0;
  bool inverted = false;
  Key128 rest_key;                    // RestKey(rest)
};

// The data of a group's shape, as the group holds it.
ShapeData ShapeOf(const ElementGroup& g) {
  return ShapeData{g.rest,         g.centre_gradient, g.centre_det,
                   g.shape_volume, g.shape_inverted,  g.rest_key};
}

// The data of rest nodes x, whose RestKey is `key`. cubic: the table's
// sum-factorized products where it has them (the Jacobians in a sixth of
// the multiply-adds, as the cell partials make them).
ShapeData IntegrateShape(const fem::KindTable& table, const fem::CubicTensorProducts* cubic,
                         const fem::NodeMatrixX3& x, const Key128& key) {
  ShapeData sd;
  sd.rest = x;
  sd.rest_key = key;
  sd.centre_det = fem::PhysicalGradients(table.centre_dn.data(), x, table.nodes, sd.centre_gradient);
  thread_local std::vector<double> j;
  if (cubic != nullptr) {
    cubic->Jacobians(x, j);
  } else {
    fem::RestJacobians(table, x, j);
  }
  for (int q = 0; q < table.points; ++q) {
    const double det = fem::JacobianAt(j, table.points, q).determinant();
    sd.inverted |= det <= 0;
    sd.volume += det * table.weight[q];
  }
  return sd;
}

// The groups of block `kind` (its node ids and cells set) and their
// elements' order: element e (rest nodes x) has material array
// material_of(e, x) and, when its rest shape is new, that shape's data
// shape_of(e, x) (called on pool threads: it must be safe to call
// concurrently). Adds the block's rest volume and inverted elements.
void GroupElements(
    ElementLayout& layout, int kind, const Points& rest,
    const std::function<int32_t(int32_t e, const fem::NodeMatrixX3& x)>& material_of,
    const std::function<ShapeData(int32_t e, const fem::NodeMatrixX3& x)>& shape_of,
    WorkerPool* pool) {
  ElementBlock& block = layout.blocks[kind];
  const int n = block.nodes;
  const int32_t count = block.size();
  block.group.resize(count);
  block.groups.clear();
  auto gather = [&](int32_t e, fem::NodeMatrixX3& x) {
    const int32_t* ids = block.element_nodes(e);
    for (int i = 0; i < n; ++i) x.row(i) = rest.row(ids[i]);
  };
  // Each element's rest shape up to translation, quantized to 1e-9 of its
  // size, as a 128-bit key (made in parallel). A group's matrices are
  // integrated over its shape's first element whatever the materials, so
  // they are a function of (shape, material samples) alone and a rebuild
  // after a paint or a restore gives the same bits as the build before it.
  std::vector<Key128> shape_key(count);
  Ranges(pool, count, [&](int64_t begin, int64_t end) {
    fem::NodeMatrixX3 x(n, 3);
    for (int64_t e = begin; e < end; ++e) {
      gather(static_cast<int32_t>(e), x);
      double size = 0;
      for (int i = 1; i < n; ++i) size = std::max(size, (x.row(i) - x.row(0)).cwiseAbs().maxCoeff());
      const double quantum = std::max(size, 1e-300) * 1e-9;
      Hash128 h;
      for (int i = 1; i < n; ++i) {
        for (int c = 0; c < 3; ++c) h.Mix(static_cast<uint64_t>(std::llround((x(i, c) - x(0, c)) / quantum)));
      }
      shape_key[e] = h.value();
    }
  });
  // Materials, shapes and groups numbered in element order.
  std::unordered_map<Key128, int32_t, Key128Hash> shape_index;
  std::unordered_map<int64_t, int32_t> group_index;  // material << 32 | shape
  std::vector<int32_t> shape_first;                   // shape -> its first element
  std::vector<int32_t> group_shape;                   // group -> shape
  fem::NodeMatrixX3 x(n, 3);
  for (int32_t e = 0; e < count; ++e) {
    gather(e, x);
    const int32_t material = material_of(e, x);
    auto [sit, new_shape] =
        shape_index.try_emplace(shape_key[e], static_cast<int32_t>(shape_first.size()));
    if (new_shape) shape_first.push_back(e);
    const int64_t group_key = static_cast<int64_t>(material) << 32 | sit->second;
    auto [git, new_group] =
        group_index.try_emplace(group_key, static_cast<int32_t>(block.groups.size()));
    block.group[e] = git->second;
    if (new_group) {
      ElementGroup grp;
      grp.representative = e;
      grp.material = material;
      block.groups.push_back(std::move(grp));
      group_shape.push_back(sit->second);
    }
  }
  // Each new shape's data, from its first element's rest nodes (in
  // parallel), then handed to its groups.
  std::vector<ShapeData> shapes(shape_first.size());
  Ranges(pool, static_cast<int64_t>(shapes.size()), [&](int64_t begin, int64_t end) {
    fem::NodeMatrixX3 xs(n, 3);
    for (int64_t k = begin; k < end; ++k) {
      gather(shape_first[k], xs);
      shapes[k] = shape_of(shape_first[k], xs);
    }
  });
  for (size_t gi = 0; gi < block.groups.size(); ++gi) {
    const ShapeData& sd = shapes[group_shape[gi]];
    ElementGroup& grp = block.groups[gi];
    grp.rest = sd.rest;
    grp.centre_gradient = sd.centre_gradient;
    grp.centre_det = sd.centre_det;
    grp.shape_volume = sd.volume;
    grp.shape_inverted = sd.inverted;
    grp.rest_key = sd.rest_key;
  }
  // Elements sorted by group, and within a group along a Z-order curve
  // of their centres (ties by index).
  const int32_t ng = static_cast<int32_t>(block.groups.size());
  block.group_start.assign(ng + 1, 0);
  for (int32_t e = 0; e < count; ++e) ++block.group_start[block.group[e] + 1];
  for (int32_t i = 0; i < ng; ++i) block.group_start[i + 1] += block.group_start[i];
  block.by_group.resize(count);
  std::vector<int32_t> fill(block.group_start.begin(), block.group_start.end() - 1);
  for (int32_t e = 0; e < count; ++e) block.by_group[fill[block.group[e]]++] = e;
  const std::vector<uint64_t> key = ZOrderKeys(block, rest);
  for (int32_t gi = 0; gi < ng; ++gi) {
    std::sort(block.by_group.begin() + block.group_start[gi],
              block.by_group.begin() + block.group_start[gi + 1],
              [&](int32_t a, int32_t b) { return key[a] != key[b] ? key[a] < key[b] : a < b; });
  }
  // Rest volume and inversion, from each group's shape.
  for (int32_t gi = 0; gi < ng; ++gi) {
    const ElementGroup& g = block.groups[gi];
    const int32_t members = block.group_start[gi + 1] - block.group_start[gi];
    layout.rest_volume += g.shape_volume * members;
    if (g.shape_inverted) layout.inverted_elements += members;
  }
}

}  // namespace

ElementLayout BuildElementLayout(const fem::ElementSet& elements, const Points& rest,
                                 const std::vector<int32_t>& cell_control_cell,
                                 const MaterialSampler& sampler, const ElementMaterials* whole,
                                 const ElementLayout* previous, WorkerPool* pool) {
  ElementLayout layout;
  MaterialTable table_of_materials(layout);
  // Arrays `whole` gave, by address: their material index once known.
  std::unordered_map<const void*, int32_t> whole_index;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const auto k = static_cast<fem::ElementKind>(kind);
    const fem::KindTable& table = layout.tables[kind] = fem::MakeKindTable(k);
    ElementBlock& block = layout.blocks[kind];
    block.kind = k;
    block.nodes = table.nodes;
    block.node_ids = NodesOfKind(elements, kind);
    block.cell = CellsOfKind(elements, kind);
    AlignElementAxes(block, rest, pool);
    std::optional<fem::CubicTensorProducts> cubic;
    if (kind == 0 && fem::CubicTensorProducts::Applies(table)) cubic.emplace(table);
    // Each element's material array: the one `whole` gives, or samples at
    // its quadrature points' rest positions; made on the pool's threads
    // (parts of 64 elements, taken as threads are free), then numbered in
    // element order (the same numbers on any number of threads).
    const int32_t count = block.size();
    std::vector<const std::vector<MaterialPoint>*> given(count, nullptr);
    std::vector<std::vector<MaterialPoint>> sampled(count);
    auto arrays = [&](int32_t begin, int32_t end) {
      fem::NodeMatrixX3 x(block.nodes, 3);
      double columns[3 * 64], positions[3 * 64];
      for (int32_t e = begin; e < end; ++e) {
        const int32_t* ids = block.element_nodes(e);
        for (int i = 0; i < block.nodes; ++i) x.row(i) = rest.row(ids[i]);
        const int32_t control_cell = cell_control_cell.empty() ? block.cell[e]
                                                               : cell_control_cell[block.cell[e]];
        const std::vector<MaterialPoint>* g =
            whole != nullptr ? (*whole)(kind, x, control_cell) : nullptr;
        if (g != nullptr && static_cast<int>(g->size()) != table.points) g = nullptr;
        given[e] = g;
        if (g != nullptr) continue;
        std::vector<MaterialPoint>& samples = sampled[e];
        samples.resize(table.points);
        if (cubic) {
          // A cubic element's point positions sum-factorized
          // (fem::CubicTensorProducts::Values: a fifth of N x's 64 x 64
          // multiply-adds), equal to SamplePosition's up to rounding.
          for (int m = 0; m < 64; ++m) {
            for (int r = 0; r < 3; ++r) columns[64 * r + m] = x(m, r);
          }
          cubic->Values(columns, 64, 3, positions, 64);
          for (int q = 0; q < 64; ++q) {
            samples[q] = sampler(
                Eigen::Vector3d(positions[q], positions[64 + q], positions[128 + q]), control_cell);
          }
        } else {
          for (int q = 0; q < table.points; ++q) {
            samples[q] = sampler(SamplePosition(table, q, x), control_cell);
          }
        }
      }
    };
    constexpr int32_t kPart = 64;
    const int parts = static_cast<int>((count + kPart - 1) / kPart);
    if (pool != nullptr && pool->size() > 1 && parts > 1) {
      pool->RunParts(parts, [&](int k) { arrays(k * kPart, std::min(count, (k + 1) * kPart)); });
    } else {
      arrays(0, count);
    }
    std::vector<int32_t> material(count);
    for (int32_t e = 0; e < count; ++e) {
      if (given[e] == nullptr) {
        material[e] = table_of_materials.Add(sampled[e]);
        sampled[e] = std::vector<MaterialPoint>();
        continue;
      }
      auto w = whole_index.find(given[e]);
      if (w == whole_index.end()) {
        w = whole_index.emplace(given[e], table_of_materials.Add(*given[e])).first;
      }
      material[e] = w->second;
    }
    auto material_of = [&material](int32_t e, const fem::NodeMatrixX3&) { return material[e]; };
    // A shape `previous` has a group of (the same rest nodes, to the bit)
    // takes that group's data: the same as integrating it again.
    std::unordered_map<Key128, int32_t, Key128Hash> known;
    const ElementBlock* was = previous != nullptr ? &previous->blocks[kind] : nullptr;
    if (was != nullptr && was->nodes == block.nodes) {
      for (size_t g = 0; g < was->groups.size(); ++g) {
        known.try_emplace(was->groups[g].rest_key, static_cast<int32_t>(g));
      }
    }
    auto shape_of = [&](int32_t, const fem::NodeMatrixX3& x) {
      const Key128 key = RestKey(x);
      const auto it = known.find(key);
      if (it != known.end() && was->groups[it->second].rest == x) {
        return ShapeOf(was->groups[it->second]);
      }
      return IntegrateShape(table, cubic ? &*cubic : nullptr, x, key);
    };
    GroupElements(layout, kind, rest, material_of, shape_of, pool);
  }
  return layout;
}

ElementLayout RelayoutMaterials(const ElementLayout& previous, const Points& rest,
                                const ElementArrays& arrays) {
  ElementLayout layout;
  MaterialTable table_of_materials(layout);
  // previous's arrays (distinct by content) by their new index.
  std::vector<int32_t> kept(previous.materials.size(), -1);
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    layout.tables[kind] = previous.tables[kind];
    const ElementBlock& was = previous.blocks[kind];
    ElementBlock& block = layout.blocks[kind];
    block.kind = was.kind;
    block.nodes = was.nodes;
    block.node_ids = was.node_ids;
    block.cell = was.cell;
    auto material_of = [&](int32_t e, const fem::NodeMatrixX3&) {
      const std::vector<MaterialPoint>* given = arrays(kind, e);
      if (given != nullptr) return table_of_materials.Add(*given);
      const int32_t old = was.groups[was.group[e]].material;
      if (kept[old] < 0) kept[old] = table_of_materials.Add(previous.materials[old]);
      return kept[old];
    };
    // A shape's first element is the same whatever the materials: its data
    // is that of the element's group before.
    auto shape_of = [&was](int32_t e, const fem::NodeMatrixX3&) {
      return ShapeOf(was.groups[was.group[e]]);
    };
    GroupElements(layout, kind, rest, material_of, shape_of, nullptr);
  }
  return layout;
}

}  // namespace dynsolid::models
