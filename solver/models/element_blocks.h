// The elements of a solid laid out for the models: per kind, the node lists,
// each element's material sample array (one value per quadrature point:
// the paper's "parametric arrays of sample values", deduplicated), and
// groups of elements that share one rest shape (up to translation) and one
// material array, so they share one element matrix (docs/model.md 4a: "share
// one matrix between elements whose rest shape and material are equal").
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "solver/common/hash128.h"
#include "solver/fem/element_data.h"
#include "solver/fem/element_set.h"
#include "solver/mesh/points.h"

namespace dynsolid {
class WorkerPool;
}  // namespace dynsolid

namespace dynsolid::models {

// Material at one quadrature point (SI units).
struct MaterialPoint {
  double young = 0;    // Pa
  double poisson = 0;  // 1
  double density = 0;  // kg/m^3
  double damping = 0;  // kg/(m^3 s)

  double lame_lambda() const { return young * poisson / ((1 + poisson) * (1 - 2 * poisson)); }
  double lame_mu() const { return young / (2 * (1 + poisson)); }
  bool operator==(const MaterialPoint&) const = default;
};

// Material at a rest position x inside level-0 control cell `control_cell`.
using MaterialSampler = std::function<MaterialPoint(const Eigen::Vector3d& x, int32_t control_cell)>;

// An element's whole sample array, when the caller has one for an element
// of `kind` with rest nodes x (n x 3, in the layout's node order) in
// `control_cell` (a topology edit: an element whose rest nodes are those of
// an element of the solid it came from keeps that element's samples); null:
// sample it point by point. The array must stay alive while the layout is
// built.
using ElementMaterials = std::function<const std::vector<MaterialPoint>*(
    int kind, const fem::NodeMatrixX3& x, int32_t control_cell)>;

struct ElementGroup {
  int32_t representative = 0;         // an element of the group (block index)
  int32_t material = 0;               // material array id
  fem::NodeMatrixX3 rest;             // n x 3 rest nodes of the first element of its shape
  fem::NodeMatrixX3 centre_gradient;  // n x 3 physical gradients at the centre
  double centre_det = 0;              // det J0 at the centre (fem::PhysicalGradients')
  double shape_volume = 0;            // rest volume of one element of its shape
  bool shape_inverted = false;        // det J0 <= 0 at a quadrature point of its shape
  Key128 rest_key;                    // RestKey(rest), for keys of what depends on it
};

// A 128-bit hash of rest nodes' bits (ElementGroup::rest_key).
Key128 RestKey(const fem::NodeMatrixX3& rest);

struct ElementBlock {
  fem::ElementKind kind = fem::ElementKind::kLinear;
  int nodes = 0;                      // n per element
  std::vector<int32_t> node_ids;      // #elements x n
  std::vector<int32_t> cell;          // element -> level-L cell
  std::vector<int32_t> group;         // element -> group
  // Elements sorted by group, then along a Z-order curve of their rest
  // centres (consecutive ones are neighbours).
  std::vector<int32_t> by_group;
  std::vector<int32_t> group_start;   // by_group[group_start[g] .. group_start[g+1])
  std::vector<ElementGroup> groups;

  int32_t size() const { return static_cast<int32_t>(cell.size()); }
  const int32_t* element_nodes(int32_t e) const { return node_ids.data() + static_cast<size_t>(e) * nodes; }
};

struct ElementLayout {
  std::array<fem::KindTable, 3> tables;   // by kind
  std::array<ElementBlock, 3> blocks;     // by kind: cubic, linear, pyramid
  std::vector<std::vector<MaterialPoint>> materials;  // distinct sample arrays
  double rest_volume = 0;                 // m^3, sum of element rest volumes
  int32_t inverted_elements = 0;          // elements with det J0 <= 0 somewhere
};

// Consecutive elements of one group (schedule.order[kind][first ..
// first+count)), processed together as one dense matrix product; or, with
// group kPooled, consecutive elements of pooled groups of one kind (see
// ScheduleElements), each applied on its own.
inline constexpr int32_t kPooled = -1;
struct ElementBatch {
  int kind;
  int32_t group;
  int32_t first, count;
  // With batch node tables (IndexBatchNodes): the batch's nodes are
  // batch_nodes[nodes_begin .. nodes_begin + num_nodes), and element b's
  // n nodes are local_ids[local_begin + b n ..] (indices into that list).
  int64_t nodes_begin = 0, local_begin = 0;
  int32_t num_nodes = 0;
};

// The batches of every group (at most `batch_size` elements each), and
// `parts` + 1 boundaries splitting them into contiguous parts of about equal
// cost (an element of n nodes costs about n^2 + 27 n): part k runs batches
// [part_start[k], part_start[k+1]). Fixed for a layout, whatever the
// number of threads.
//
// Each part adds its elements' forces into a buffer of its own; only the
// nodes a part touches are cleared and summed: part_nodes[k] lists them
// (ascending) and node_parts[v] has bit k set when part k touches node v
// (parts <= 8).
struct ElementSchedule {
  // Per kind, the elements in the order the batches take them: each
  // group's elements as in block.by_group, in group order, pooled groups'
  // elements last (by element index).
  std::array<std::vector<int32_t>, 3> order;
  std::vector<ElementBatch> batches;
  std::vector<size_t> part_start;
  std::vector<std::vector<int32_t>> part_nodes;
  std::vector<uint8_t> node_parts;
  // Batch node tables (empty until IndexBatchNodes).
  std::vector<int32_t> batch_nodes;
  std::vector<uint16_t> local_ids;
  int32_t max_batch_nodes = 0;
};
//
// `pooled` (optional; per kind, one flag per group, or empty) marks groups
// whose elements leave their groups' batches and share kPooled batches
// with the other pooled groups' elements of their kind (groups of one or a
// few elements: a painted band, a curved mesh), for a model that applies
// them per element.
using PooledGroups = std::array<std::vector<uint8_t>, 3>;
// One flag per group of `block`: it has at most `max_members` elements (all
// zero when max_members <= 0).
std::vector<uint8_t> SmallGroups(const ElementBlock& block, int32_t max_members);
ElementSchedule ScheduleElements(const ElementLayout& layout, int32_t batch_size, int parts,
                                 int32_t num_nodes, const PooledGroups* pooled = nullptr);

// Batch node tables: per batch, the nodes its elements touch (ascending,
// each once) and each element's nodes as 16-bit indices into that list.
// A model then gathers a batch's node rows once into a small dense array,
// runs its elements on that array, and adds the batch's sums into its
// buffer once per node. On a subdivided block a batch of 64 cubic elements
// (a 4 x 4 x 4 cluster: one group, Z-order within it) touches some 350
// nodes: a node row is read from the big arrays about 5 times per element
// instead of 64, and the element loops read rows that sit in L1 (22 KB).
// The local ids are also half the bytes of global ones. Needs batch_size *
// nodes per element <= 65536.
void IndexBatchNodes(const ElementLayout& layout, ElementSchedule& schedule);

// Bytes of the batch node tables per element.
int64_t BatchTableBytes(const ElementLayout& layout, const ElementSchedule& schedule);

// Clears the rows of `buffer` that part k touches (before it adds into it).
void ClearPartRows(const ElementSchedule& schedule, int k, Points& buffer);

// out rows [begin, end) = the sum of the parts' buffers, added in part
// order: the same bits whatever the number of threads or the node range
// split. Rows no part touches become zero.
void SumPartRows(const ElementSchedule& schedule, const Points* const* buffers, int32_t begin,
                 int32_t end, Points& out);

// y (m, double) = K x for a pooled element's own small matrix K (m x m,
// row-major, entries S), x of type T, each row one S sum over j in order
// (S = float: x rounded to float as read).
template <typename S, typename T>
inline void SmallProduct(const S* k, int m, const T* x, double* y) {
  for (int i = 0; i < m; ++i) {
    const S* row = k + static_cast<int64_t>(i) * m;
    S acc = 0;
    for (int j = 0; j < m; ++j) acc += row[j] * static_cast<S>(x[j]);
    y[i] = static_cast<double>(acc);
  }
}

// Bytes a model keeps per element beyond the mesh: node ids, group id, the
// element's place in by_group, and its warm-started frame (a quaternion).
int64_t PerElementBytes(const ElementLayout& layout);

// For each group of kind `kind` in `layout`, a group of the same kind in
// `previous` with the same rest shape (bit for bit) and the same stiffness
// samples (Young's modulus and Poisson ratio at every quadrature point),
// or -1: such groups have the same element stiffness matrices, so a model
// rebuilt after a paint can take them over instead of integrating again.
std::vector<int32_t> MatchStiffnessGroups(const ElementLayout& layout,
                                          const ElementLayout& previous, int kind);

// The rest position of quadrature point q of an element of `table` with
// rest nodes x (n x 3): where BuildElementLayout samples its material.
inline Eigen::Vector3d SamplePosition(const fem::KindTable& table, int q,
                                      const fem::NodeMatrixX3& x) {
  const Eigen::Map<const Eigen::Matrix<double, 1, Eigen::Dynamic>> nq(table.N(q), table.nodes);
  return (nq * x).transpose();
}

// Builds the layout. `rest` holds the rest FEM node positions (#nodes by 3),
// `cell_control_cell` maps level-L cells to control cells for the sampler.
// `whole` (optional) is asked first for each element. `previous`
// (optional): a layout built before, whose groups' shape data (a function
// of their rest nodes alone) a shape with the same rest nodes takes
// instead of integrating them again (a topology edit). `pool` (optional):
// threads for the elements' material arrays, the shapes' keys and their
// integrals: the sampler and `whole` are called on its threads at once
// (they must be safe to call concurrently). The result does not depend on
// the threads.
ElementLayout BuildElementLayout(const fem::ElementSet& elements, const Points& rest,
                                 const std::vector<int32_t>& cell_control_cell,
                                 const MaterialSampler& sampler,
                                 const ElementMaterials* whole = nullptr,
                                 const ElementLayout* previous = nullptr,
                                 WorkerPool* pool = nullptr);

// Element e of `kind`'s new sample array (table.points samples), or null
// when it keeps the one it has.
using ElementArrays = std::function<const std::vector<MaterialPoint>*(int kind, int32_t e)>;

// The layout BuildElementLayout gives, bit for bit, for the elements and
// rest nodes `previous` was built from, with each element's samples those
// `arrays` gives it (or its samples in `previous`): materials, shapes and
// groups numbered as BuildElementLayout numbers them, without sampling or
// integrating anything (a paint, an undo to another material).
ElementLayout RelayoutMaterials(const ElementLayout& previous, const Points& rest,
                                const ElementArrays& arrays);

}  // namespace dynsolid::models
