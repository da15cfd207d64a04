// Corotational linear elasticity (docs/model.md 4b; Mueller and Gross 2004):
// the standard comparison for the paper's local-frame model.
//
// Per element group (shared rest shape up to translation and material) the
// full element stiffness
//   K = integral B^T C B dV          (3n x 3n, N/m),
// B the 6 x 3n strain-displacement matrix of the physical rest gradients
// G = dN J0^-1 at each quadrature point (strains xx, yy, zz and the
// engineering shears xy, yz, zx), C the isotropic matrix of the point's
// Lame parameters, dV the rest volume. Ordering is node-major:
// [x0 y0 z0 x1 y1 z1 ...], so an n x 3 row-major block of node vectors is
// one column of the product. K is symmetric positive semi-definite with
// the six rigid motions of the rest nodes as its null space.
//
// Per step, for each element e with nodes d_i (current) and x0_i (its own
// rest positions, not the group's: groups share shape only up to
// translation) and centroids dbar, x0bar:
//   F   = sum_i d_i (x) G_centre_i          (deformation gradient at centre)
//   R_e = rotation of F (warm started, rotation.h)
//   u_i = R_e^T (d_i - dbar) - (x0_i - x0bar)
//   g_i += R_e (K u)_i,        E += 1/2 u . K u.
// Subtracting the centroids changes nothing in exact arithmetic (K kills
// translations) and keeps large coordinates out of the product. Rigid motion
// gives u = 0, hence no force. The force is the gradient of E with the
// frames held fixed (the standard corotational force, no dR/dd term).
//
// Elements of one group are processed in batches as dense products: the
// shared K times a 3n x batch block of local displacements. Cubic groups
// of at most `quadrature_group_size` elements (by default all of them) have
// no matrix: their elements share kPooled batches and K u is taken at their
// quadrature points (cubic_quadrature.h, the isotropic law). A dense
// 192 x 192 per element would be integrated on every paint and streamed
// from memory on every pass; shared by a whole block, its products are
// still slower (bench/quadrature_bench). Linear and pyramid groups of at
// most kQuadratureGroupSize elements (a curved mesh's) share kPooled
// batches too and keep their K, applied by plain products.
#pragma once

#include <array>
#include <atomic>
#include <mutex>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "solver/common/worker_pool.h"
#include "solver/models/cubic_quadrature.h"
#include "solver/models/element_blocks.h"
#include "solver/models/internal_force.h"
#include "solver/models/panel_product.h"

namespace dynsolid::models {

// Plasticity's hook into the per-element corotation (material/plasticity.h
// implements it, as it does cell_corotation.h's CellFlow): each element's
// rest shape moved by offsets u_p (3 per node, node-major, rest frame):
//
//   u_e = R_e^T (d - dbar) - (x0 - x0bar) - u_p,   R_e = rotation of F F_p^-1,
//   F_p = I + sum_i u_pi G_centre_i^T,
//
// so that the plastically deformed rest shape, moved rigidly, carries no
// force. A pass that finds frames (Forces) calls Flow for each plastic
// element after its product, on the pool's threads, when flowing(): Flow
// may change that element's offsets only.
class ElementFlow {
 public:
  virtual ~ElementFlow() = default;
  // Element `element` of kind block `kind`'s offsets (3 n values); null:
  // the element is elastic (its material never yields and it never flowed).
  virtual const double* offsets(int kind, int32_t element) const = 0;
  virtual bool flowing() const = 0;
  // The element's elastic local displacement u and K u (3 n each).
  virtual void Flow(int kind, int32_t element, const double* u, const double* ku) = 0;
};

class CorotationalModel final : public InternalForceModel {
 public:
  // `layout` and `pool` must outlive the model; `rest` (#nodes by 3, metres:
  // the FEM nodes at rest, the positions `layout` was built from) is copied.
  // With `previous` (a model of the same mesh, e.g. before a paint), groups
  // whose rest shape and stiffness samples it already had take its matrices
  // (see MatchStiffnessGroups).
  //
  // The element products (the groups' matrices, the cubic elements'
  // quadrature factors, the batches' schedule and scratch) are made here,
  // or with Products::kWhenUsed on the first call that needs them (Forces,
  // UpdateFrames, AffineForces, ApplyLinearized, K), without `previous`: a
  // solid corotated per control cell (cell_corotation.h) keeps this model
  // for its frames and group choices only, and never calls them.
  enum class Products { kNow, kWhenUsed };
  CorotationalModel(const ElementLayout& layout, const Points& rest, WorkerPool& pool,
                    const CorotationalModel* previous = nullptr,
                    int32_t quadrature_group_size = kEveryGroup,
                    Products products = Products::kNow);
  CorotationalModel(const CorotationalModel&) = delete;
  CorotationalModel& operator=(const CorotationalModel&) = delete;

  double Forces(const Points& d, Points& g) override;
  void ResetFrames() override;
  InternalForceModel::Frames frames() const override { return frames_; }
  void set_frames(const InternalForceModel::Frames& frames) override { frames_ = frames; }
  std::string_view name() const override { return "corotational"; }
  void set_pool(WorkerPool& pool) override { pool_ = &pool; }
  Timing last_timing() const override { return timing_; }

  // out (#nodes by 3, N) = sum_e R_e K R_e^T P v_e for v (#nodes by 3, m):
  // the linearization of Forces with the frames of the last Forces call held
  // fixed (P removes the element's mean, which K ignores anyway). Symmetric
  // positive semi-definite in v. Identity frames before the first Forces call
  // or after ResetFrames. For matrix-free CG in backward Euler.
  // Uses the model's scratch buffers: not concurrent with Forces or itself.
  // Like Forces, allocates nothing once `out` has #nodes rows.
  void ApplyLinearized(const Points& v, Points& out) const;

  // ApplyLinearized with K in single precision (PackedMatrixF: the element
  // columns rounded to float, float products, results widened to double),
  // about twice as fast, relative error about 1e-6: for an iteration whose
  // residual is recomputed in double elsewhere (backward Euler's CG at a
  // tolerance of 1e-5 or looser). Off by default; on builds the float
  // copies of the group matrices (half their bytes again), off frees them.
  // Forces and AffineForces stay in double.
  void SetSinglePrecisionLinearized(bool on);
  bool single_precision_linearized() const { return single_; }

  // Backward Euler's folded right-hand side (frames fixed for a step, the
  // force is affine in the positions, so g(d) + K_R v h = g_R(d + h v): one
  // pass instead of two). UpdateFrames extracts the frames at d (#nodes by 3,
  // metres), exactly as Forces(d) would, without the element products.
  // AffineForces then gives, with those frames held,
  //   g (#nodes by 3, N) = sum_e R_e K (R_e^T (x_e - xbar) - (x0_e - x0bar)),
  // and returns 1/2 sum_e u_e . K u_e (J), the strain energy of x in the
  // held frames. AffineForces(d) after UpdateFrames(d) equals Forces(d) bit
  // for bit. Same scratch, allocation and timing rules as Forces.
  void UpdateFrames(const Points& d);
  double AffineForces(const Points& x, Points& g);

  // Group `group`'s stiffness of kind block `kind` (0 cubic, 1 linear,
  // 2 pyramid): 3n x 3n, node-major, N/m.
  // A group applied at its quadrature points has it made here from them
  // (CubicQuadratureElements::Matrix).
  Eigen::MatrixXd K(int kind, int32_t group) const;
  // Whether the element products are made (always, with Products::kNow).
  bool has_products() const { return products_.load(std::memory_order_acquire); }
  // Whether K(kind, group) is made from the group's quadrature points.
  bool at_quadrature_points(int kind, int32_t group) const { return kind == 0 && pooled_[0][group]; }
  // Cubic elements applied at their quadrature points.
  int64_t quadrature_elements() const { return quadrature_.size(); }
  // Bytes of the shared group matrices (float copies included); bytes per element of per-element
  // state (node ids, group id, place in by_group, warm-started frame), as
  // LocalFrameModel counts them. The copy of the rest positions (24 bytes
  // per node) is in neither.
  int64_t shared_matrix_bytes() const;
  int64_t per_element_bytes() const;

  // The plastic flow hook (null: elastic; the default).
  void set_flow(ElementFlow* flow) { flow_ = flow; }
  const ElementLayout& layout() const { return layout_; }

 private:
  struct Workspace {
    Points g;
    Eigen::MatrixXd u, y;  // 3n x batch local displacements and forces
    Eigen::MatrixXf uf;    // u in float (single-precision ApplyLinearized)
    double energy = 0;
  };
  using Frames = std::array<std::vector<Eigen::Quaterniond>, 3>;
  // Runs batches [begin, end) into w. With `update` (Forces): x = d, the
  // frames are extracted into *update and u = R^T (d - dbar) - (x0 - x0bar).
  // Without (ApplyLinearized): x = v, the frames are read from frames_ and
  // u = R^T (v - vbar).
  // `subtract_rest` (AffineForces): frames read from frames_, u as in Forces.
  void RunBatches(int part, const Points& x, Frames* update, Workspace& w,
                  bool subtract_rest = false) const;
  void FrameBatches(int part, const Points& d);  // UpdateFrames' part
  void SumParts(Points& out) const;  // out = sum of the parts' buffers
  // The element products (the constructor's, or EnsureProducts' on first
  // use); `previous` as the constructor's.
  void BuildProducts(const CorotationalModel* previous);
  void EnsureProducts() const;
  mutable std::once_flag products_once_;
  std::atomic<bool> products_{false};  // read by ModelCopy's thread (has_products)

  const ElementLayout& layout_;
  WorkerPool* pool_;
  ElementFlow* flow_ = nullptr;
  Points rest_;
  int32_t num_nodes_;
  // packed_[kind][group]: 3n x 3n.
  std::array<std::vector<PackedMatrix>, 3> packed_;  // packed for the products
  std::array<std::vector<PackedMatrixF>, 3> packed_f_;  // float copies, when on
  bool single_ = false;
  // Per kind and group: pooled (ScheduleElements). Pooled cubic groups are
  // applied at their quadrature points (no matrix in packed_; quadrature_
  // holds those elements' factors); pooled linear and pyramid groups (at
  // most kQuadratureGroupSize elements) by plain products with their K in
  // small_ (3n x 3n row-major) and small_f_ (float, when single_).
  PooledGroups pooled_;
  std::array<std::vector<std::vector<double>>, 3> small_;
  std::array<std::vector<std::vector<float>>, 3> small_f_;
  CubicQuadratureElements quadrature_;
  Frames frames_;  // per element, by kind; written by Forces only
  ElementSchedule schedule_;  // batches and their fixed parts
  // Per-part scratch, allocated at construction (mutable for the const
  // ApplyLinearized).
  mutable std::vector<Workspace> work_;
  int32_t integrated_groups_ = 0;

 public:
  // Groups whose matrices were integrated (not taken over) at construction.
  int32_t integrated_groups() const { return integrated_groups_; }
  std::vector<const Points*> part_buffers_;
  Timing timing_;
};

}  // namespace dynsolid::models
