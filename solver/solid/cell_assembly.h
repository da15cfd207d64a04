// Control-space matrices (the mass Mt and damping Dt, backward Euler's K0)
// summed control cell by control cell, each cell's partial sum remembered
// under a key of everything it is made of, so that the next build (a paint,
// a topology edit) makes anew only the cells that changed.
//
// Every such matrix is a sum of element blocks E_e^T X_e E_e, E_e the
// element's rows of the node matrix on its control support. Here it is
// summed in a fixed order: per control cell, its elements (kind order, then
// block order) into a partial over the cell's support; then the partials in
// cell order. A cell's partial is a function of its key alone: its
// elements' group contents (the caller's GroupKey: rest shape, material,
// anything the element's X depends on) and node rows, the control points
// numbered within the cell's support. A renumbering that keeps their order
// (cells deleted, points appended) keeps the key. So a matrix summed with
// the partials of an earlier build has the bits of one summed from scratch,
// and a solid rebuilt from its scene (crash recovery) equals the edited one.
#pragma once

#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "solver/common/worker_pool.h"
#include "solver/models/element_blocks.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {

using Key128 = std::pair<uint64_t, uint64_t>;

// A 128-bit hash (FNV-1a and a multiplicative mix), for cache keys and
// fingerprints.
class Hash128 {
 public:
  void Mix(uint64_t x) {
    h1_ = (h1_ ^ x) * 1099511628211ull;
    h2_ = (h2_ ^ (x + 0x632be59bd9b4e019ull + (h2_ << 6) + (h2_ >> 2))) * 0xff51afd7ed558ccdull;
  }
  void Double(double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, sizeof(bits));
    Mix(bits);
  }
  void Doubles(const double* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) Double(v[i]);
  }
  void Ints(const int32_t* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) Mix(static_cast<uint32_t>(v[i]));
  }
  void Bytes(std::string_view s) {
    Mix(s.size());
    for (unsigned char c : s) Mix(c);
  }
  void Key(const Key128& k) {
    Mix(k.first);
    Mix(k.second);
  }
  Key128 value() const { return {h1_, h2_}; }

 private:
  uint64_t h1_ = 1469598103934665603ull, h2_ = 0x9e3779b97f4a7c15ull;
};

// An element's rows of the node matrix restricted to its control support:
// B (n x s), support[a] the control point of column a (ascending).
struct ElementRows {
  std::vector<int32_t> support;
  Eigen::MatrixXd b;
};

struct Key128Hash {
  size_t operator()(const Key128& k) const { return static_cast<size_t>(k.first ^ (k.second * 31)); }
};

// The partials of one build, by cell key, for the next.
struct CellPartials {
  // A cell's partial over its support (S points): outputs matrices of dofs S square.
  std::unordered_map<Key128, std::shared_ptr<const std::vector<Eigen::MatrixXd>>, Key128Hash> by_key;
  int32_t cells = 0;  // control cells summed
  int32_t made = 0;   // distinct partials made in this build (not carried)
  double bytes = 0;
};

struct CellSumSpec {
  int dofs = 1;     // rows per control point (1: mass; 3: stiffness, node-major 3 i + c)
  int outputs = 1;  // matrices summed side by side (mass and damping: 2)
  uint64_t salt = 0;  // what else the blocks depend on (settings)
  // A key of everything the blocks of a group's elements depend on besides
  // their node rows.
  std::function<Key128(int kind, int32_t group)> group_key;
  // The blocks of element e (kind) over its support: outputs matrices of
  // dofs s square. Elements of one group with equal B get the same blocks
  // (made once per thread and cell batch).
  std::function<void(int kind, int32_t e, const ElementRows& rows,
                     std::vector<Eigen::MatrixXd>& blocks)>
      make;
};

// The sums, dense (dofs #control square) or as triplets in cell order.
struct CellSums {
  bool dense = true;
  std::vector<Eigen::MatrixXd> matrices;
  std::vector<std::vector<Eigen::Triplet<double, int32_t>>> triplets;
};

// Sums the layout's element blocks as above into out (dense when `dense`).
// previous: the partials of an earlier build (null: none). Returns this
// build's partials (to carry to the next unless bytes is above what it is
// worth keeping: kMaxCarriedBytes).
std::shared_ptr<CellPartials> SumByCell(const subdivision::SparseMatrix& nm,
                                        const models::ElementLayout& layout,
                                        const std::vector<int32_t>& control_cell,
                                        int32_t control_cells, const CellSumSpec& spec,
                                        const CellPartials* previous, WorkerPool& pool, bool dense,
                                        CellSums& out);

// Partials above this many bytes are not carried to the next build.
inline constexpr double kMaxCarriedBytes = 64.0 * 1048576.0;

}  // namespace dynsolid::solid
