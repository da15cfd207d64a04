// The local-frame model's products for cubic elements that share no
// matrix with others (a painted band, where every element has a material
// of its own; a curved mesh, where every element has a shape of its own),
// applied at the quadrature points instead of through a dense matrix.
//
// With g_c(q) the physical gradients of the 64 shape functions at point q
// (direction c) and dV(q) its rest volume weight, the element's three
// matrices are K_a = sum_q sum_c k_ac(q) g_c(q) g_c(q)^T with
// k_aa = dV (lambda + 2 mu) and k_ac = dV mu for c != a (local_frame.h).
// g_c(q) = sum_k dN_k(q) Jinv(k, c) with dN the reference gradients
// (shared by every cubic element) and Jinv the inverse rest Jacobian at q,
// so K_a x takes
//   r_k(q) = dN_k(q) . x               (reference gradients of x)
//   p_c = sum_k r_k Jinv(k, c),  s_c = k_ac p_c,  t_k = sum_c Jinv(k, c) s_c
//   y = sum_q sum_k t_k(q) dN_k(q).
// The first and last lines run sum-factorized: node m = 16 i + 4 j + k
// carries B_i(u) B_j(v) B_k(w) (fem::CubicShape) and point q = 16 qi + 4 qj
// + qk the 1D Gauss points (u_qi, v_qj, w_qk) (fem::TableFor), so dN_u(q) .
// x is three 1D contractions (B' along u, B along v and w), 8 of them for
// the three gradients with shared partial sums: 2 x 2048 multiply-adds a
// component each way, against 4096 for a dense 64 x 64 product.
//
// What an element keeps is 11 numbers per point (Jinv, dV lambda, dV mu),
// 5.6 KB in double, against 48 KB (float) to 96 KB (double) for its three
// dense matrices: on a curved or painted solid the dense path streams its
// matrices from memory on every pass, this one stays in cache. Building
// the factors takes a Jacobian inverse per point instead of integrating
// three 64 x 64 matrices (a paint's rebuild).
//
// Elements are taken kQuadratureLanes at a time, one per lane: every loop
// runs over the lanes innermost, so it vectorizes without shuffles, and an
// element's result does not depend on its lane or on the others (each
// lane's arithmetic is the same sequence of operations).
#pragma once

#include <cstdint>
#include <vector>

#include "solver/fem/element_data.h"
#include "solver/models/element_blocks.h"

namespace dynsolid::models {

inline constexpr int kQuadratureLanes = 8;

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
// material samples `material` (64) into lane `lane` of chunk `chunk`.
void SetCubicQuadratureFactors(const fem::KindTable& table, const fem::NodeMatrixX3& rest,
                               const std::vector<MaterialPoint>& material, double* chunk,
                               int lane);

// y_a (64 x count, column stride ld, doubles) = K_a x_a for a = 0, 1, 2 and
// the `count` <= kQuadratureLanes elements of chunk `factors` (x_a: 64 x
// count, column stride ld, T = float or double). S is the arithmetic:
// double, or float (with float factors, as the float dense products).
template <typename S, typename T>
void ApplyCubicQuadrature(const CubicQuadratureBasis& basis, const S* factors, int count,
                          const T* const x[3], int ld, double* const y[3]);

}  // namespace dynsolid::models
