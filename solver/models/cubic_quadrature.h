// The element products of cubic elements that share no matrix with others
// (a painted band, where every element has a material of its own; a curved
// mesh, where every element has a shape of its own), applied at the
// quadrature points instead of through dense element matrices.
//
// With g_c(q) the physical gradients of the 64 shape functions at point q
// (direction c), g_c(q) = sum_k dN_k(q) Jinv(k, c) with dN the reference
// gradients (the same for every cubic element) and Jinv the inverse rest
// Jacobian at q, an element product takes, per point,
//   r_ak = dN_k(q) . x_a             (reference gradients of component a)
//   H_ac = sum_k r_ak Jinv(k, c)     (physical gradients)
//   s = the point's law applied to H, times dV(q)
//   t_ak = sum_c Jinv(k, c) s_ac,   y_a += sum_k t_ak dN_k(q).
// The laws:
//  - kLocalFrame (local_frame.h): s_ac = k_ac H_ac with k_aa = lambda +
//    2 mu, k_ac = mu (c != a): the three matrices K_a, each component on
//    its own;
//  - kIsotropic (corotational.h): s = lambda tr(H) I + mu (H + H^T), the
//    stress of linear elasticity: K = int B^T C B dV.
// The first and last lines run sum-factorized: node m = 16 i + 4 j + k
// carries B_i(u) B_j(v) B_k(w) (fem::CubicShape) and point q = 16 qi + 4 qj
// + qk the 1D Gauss points (u_qi, v_qj, w_qk) (fem::MakeKindTable), so the
// three reference gradients of a component are 8 one-dimensional 4 x 4
// contractions with shared partial sums, 2048 multiply-adds, and as many
// back: the multiply-adds of a dense 64 x 64 product, without its matrix.
//
// What an element keeps is 11 numbers per point (Jinv, dV lambda, dV mu),
// 5.6 KB in double, against 48 KB (float) to 96 KB (double) for the local
// frame's three dense matrices and 288 KB for the corotational 192 x 192:
// on a curved or painted solid the dense path streams its matrices from
// memory on every pass, this one stays in cache. Building the factors takes
// a Jacobian inverse per point instead of integrating matrices (a paint's
// rebuild).
//
// Elements are taken kQuadratureLanes at a time, one per lane, their three
// components side by side (24 lanes): every loop runs over the lanes
// innermost, so it vectorizes without shuffles, and an element's result
// does not depend on its lane or on the others (each lane's arithmetic is
// the same sequence of operations).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "solver/fem/element_data.h"
#include "solver/models/element_blocks.h"

namespace dynsolid::models {

inline constexpr int kQuadratureLanes = 8;

// Cubic groups of at most this many elements are applied at their
// quadrature points by the local-frame model: a larger group shares its
// three 64 x 64 matrices among enough elements for the dense products to
// be faster (bench/quadrature_bench). The corotational model applies every
// cubic group there (kEveryGroup): the quadrature points beat its 192 x 192
// products even when one matrix serves a whole block.
inline constexpr int32_t kQuadratureGroupSize = 8;
inline constexpr int32_t kEveryGroup = 1 << 30;

// The 1D cubic B-spline values and derivatives at the cubic rule's 4 Gauss
// points, [point][function].
struct CubicQuadratureBasis {
  double b[4][4], db[4][4];
  float bf[4][4], dbf[4][4];
  // The basis of `table` (a cubic kind table of 4 x 4 x 4 points); checks
  // that the tensor products reproduce table.dN to 1e-12 (false when not).
  static bool Make(const fem::KindTable& table, CubicQuadratureBasis& out);
};

// Per chunk of kQuadratureLanes elements, per point, kFactorsPerPoint
// values, each a row of kQuadratureLanes (one per element): Jinv row-major
// (9), then dV lambda, then dV mu.
inline constexpr int kFactorsPerPoint = 11;
inline constexpr int64_t kChunkValues = int64_t{64} * kFactorsPerPoint * kQuadratureLanes;

// Writes the factors of a cubic element with rest nodes `rest` (64 x 3) and
// material samples `material` (64) into lane `lane` of chunk `chunk`; dV
// is the rest volume weight times `scale` (local_frame.h kStiffnessFactor).
void SetCubicQuadratureFactors(const fem::KindTable& table, const fem::NodeMatrixX3& rest,
                               const std::vector<MaterialPoint>& material, double scale,
                               double* chunk, int lane);

// What a point does with the gradients: the local-frame model's three
// matrices (each component on its own) or isotropic linear elasticity (the
// corotational model's K = int B^T C B dV).
enum class CubicPointLaw { kLocalFrame, kIsotropic };

// For the `count` <= kQuadratureLanes elements of chunk `factors`:
//  - kLocalFrame: y_a = K_a x_a for a = 0, 1, 2 (local_frame.h);
//  - kIsotropic: y = K x with x, y the elements' node vectors (corotational.h).
// Component a of node m of element l is x[a][l ld + m node_stride] (T =
// float or double), y alike (double). S is the arithmetic: double, or float
// (with float factors, as the float dense products).
template <CubicPointLaw kLaw, typename S, typename T>
void ApplyCubicQuadrature(const CubicQuadratureBasis& basis, const S* factors, int count,
                          const T* const x[3], int64_t ld, int node_stride, double* const y[3]);

// A model's pooled cubic elements (ScheduleElements' kPooled batches) and
// their factors, in the schedule's order.
class CubicQuadratureElements {
 public:
  // Flags (one per cubic group of `layout`) the groups of at most
  // `group_size` elements; none when group_size <= 0 or the cubic table is
  // not the tensor rule the sum factorization reads.
  std::vector<uint8_t> Choose(const ElementLayout& layout, int32_t group_size);
  // The factors of the pooled elements of `schedule` (made with Choose's
  // flags); dV scaled by `scale`.
  void Build(const ElementLayout& layout, const ElementSchedule& schedule, double scale);
  // Keeps a float copy of the factors (for S = float), or frees it.
  void SetFloat(bool on);

  int64_t size() const { return size_; }
  int64_t bytes() const {
    return static_cast<int64_t>(factors_.size()) * 8 + static_cast<int64_t>(factors_f_.size()) * 4;
  }
  // The dense matrix of a pooled group's elements, from the quadrature
  // points (24 products of 8 unit columns; far cheaper than integrating):
  // kIsotropic the 192 x 192 node-major K, kLocalFrame the 64 x 64 K_axis.
  // Symmetrized ((K + K^T) / 2, as the integrated matrices).
  Eigen::MatrixXd Matrix(CubicPointLaw law, const ElementLayout& layout, int32_t group,
                         double scale, int axis = 0) const;
  // ApplyCubicQuadrature for the pooled batch of schedule elements [first,
  // first + count), a chunk at a time (x, y, ld, node_stride as there: the
  // batch's first element at x[a][0]).
  template <CubicPointLaw kLaw, typename S, typename T>
  void Apply(int32_t first, int32_t count, const T* const x[3], int64_t ld, int node_stride,
             double* const y[3]) const;

 private:
  CubicQuadratureBasis basis_{};
  std::vector<double> factors_;
  std::vector<float> factors_f_;
  int32_t first_ = 0;  // the first pooled element's place in the schedule order
  int64_t size_ = 0;
};

}  // namespace dynsolid::models
