// The paper's local-frame stiffness model (docs/model.md 4a).
//
// Per element group (shared rest shape and material) three n x n matrices,
// reading Eq. 15 as the diagonal blocks of the full element stiffness
// (K_x = K^x_x + K^y_x + K^z_x with K^x_x = int (lambda + 2 mu) G_x G_x^T,
// K^y_x = int mu G_y G_y^T, K^z_x = int mu G_z G_z^T; G the physical
// gradients of the shape functions at rest): symmetric, each with the
// constants as its null space. The paper's cross-coupling blocks K_xy ...
// are dropped, as Eq. 15 prints.
//
// Per step: delta = R(d) (edge stretch and corner shear, measure.h); per
// element the frame R_e = rotation of the deformation gradient at the
// element centre (warm started); dhat = R_e^T delta; y = sum_e R_e
// diag(K_x, K_y, K_z) dhat. Elements of one group are processed in batches
// as dense matrix products (the shared K times a block of dhat columns).
// A batch gathers the rows (d, delta) of the nodes it touches once into a
// small aligned array, its elements read them there by 16-bit local ids,
// and its sums are added into the part's buffer once per node
// (IndexBatchNodes, element_blocks.h); the rows of the batch two ahead
// are prefetched while it runs.
// Strain energy E = 1/2 sum dhat . K dhat.
//
// The force is the gradient of E with the frames held fixed:
// g = (d delta / d d)^T y. docs/model.md 4a reads the force as y itself
// (R_e K_i dhat on the nodes); that operator is not symmetric: on the beam
// scene its linearization at rest has an antisymmetric part of 17 % and 15
// negative eigenvalues, so the solid drifts away from rest with any time
// step. The pull-back keeps the paper's measure, frames and matrices, and
// makes the model conservative (symmetric positive semi-definite stiffness
// at rest, with the rigid motions as its null space).
//
// Element products in single precision (`float_products`, the default for
// stepping; SolverSettings.element_products): K is rounded to float once,
// each element's dhat columns are rounded as they are formed, the products
// run in float lanes (twice the lanes of double, half the bytes of K) and
// their results are widened to double before the rotation back and the
// sums over elements. The force's error is about 1e-7 of its largest
// entry (2e-8 measured on the mixed scene: K dhat over 64 terms, and dhat
// carries no rigid part to cancel), three orders below the conjugate
// gradient's 1e-4 in the step it feeds; a rigidly moved
// solid still has zero force (delta is zero before any rounding).
// ExactForces runs the double products, for finite differences and
// comparisons. With float products, a cubic group whose matrices are a sum
// of Kronecker products of 1D B-spline integrals (an axis-aligned box of
// one material: every interior element of a block) applies them
// sum-factorized (kron_product.h), within the same rounding.
//
// Groups of at most `quadrature_group_size` elements (a painted band,
// where every element has a material of its own; a curved mesh, where
// every element has a shape of its own) leave their own batches of one or
// a few elements for kPooled batches of their kind. Cubic ones have no
// dense matrices: they are applied at their quadrature points from
// per-element factors (cubic_quadrature.h), in float with float products;
// a dense matrix per element would be streamed from memory on every pass
// (the torus's 87 MB) and integrated on every paint. Linear and pyramid
// ones keep their small matrices, applied by plain products: a batch of
// one element wasted most of a panel product and all of a batch's
// gathers.
//
// Note on Eq. 15's factor 2 (docs/model.md writes K^x_x = 2 int ...): with it,
// E would not keep its meaning in pascals (the energy 1/2 eps C eps gives
// int B^T C B); kStiffnessFactor = 1 keeps E in pascals.
#pragma once

#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "solver/common/worker_pool.h"
#include "solver/models/cubic_quadrature.h"
#include "solver/models/element_blocks.h"
#include "solver/models/internal_force.h"
#include "solver/models/kron_product.h"
#include "solver/models/measure.h"
#include "solver/models/panel_product.h"

namespace dynsolid::models {

inline constexpr double kStiffnessFactor = 1.0;


class LocalFrameModel final : public InternalForceModel {
 public:
  // `layout` and `pool` must outlive the model.
  // With `previous` (a model of the same mesh, e.g. before a paint), groups
  // whose rest shape and stiffness samples it already had take its matrices
  // (the same bits as integrating them again; see MatchStiffnessGroups).
  LocalFrameModel(const ElementLayout& layout, DeformationMeasure measure, int32_t num_nodes,
                  WorkerPool& pool, const LocalFrameModel* previous = nullptr,
                  bool float_products = false,
                  int32_t quadrature_group_size = kQuadratureGroupSize);

  // The deformation measure (it depends on the mesh alone: a model rebuilt
  // after a paint copies it).
  const DeformationMeasure& measure() const { return measure_; }
  // Groups whose matrices were integrated (not taken over) at construction.
  int32_t integrated_groups() const { return integrated_groups_; }
  // Cubic groups whose products run sum-factorized (kron_product.h), and
  // the elements in them.
  int32_t factorized_groups() const;
  int64_t factorized_elements() const;
  // Cubic elements applied at their quadrature points.
  int64_t quadrature_elements() const { return quadrature_.size(); }

  double Forces(const Points& d, Points& g) override;
  double ExactForces(const Points& d, Points& g) override;
  bool float_products() const { return float_products_; }
  void ResetFrames() override;
  InternalForceModel::Frames frames() const override;
  void set_frames(const InternalForceModel::Frames& frames) override;
  std::string_view name() const override { return "local_frame"; }
  void set_pool(WorkerPool& pool) override { pool_ = &pool; }
  Timing last_timing() const override { return timing_; }

  // The three matrices of group `group` of kind block `kind` (tests, reports).
  // A group applied at its quadrature points has its matrices made here
  // from them (CubicQuadratureElements::Matrix, in double).
  Eigen::MatrixXd K(int kind, int32_t group, int axis) const;
  int64_t shared_matrix_bytes() const;
  // The layout's per-element bytes (element_blocks.h) plus the measure's
  // edge and corner lists spread over the elements.
  int64_t per_element_bytes() const;

 private:
  struct Workspace {
    Points g;  // this part's sum of R_e K dhat (rows of its nodes only)
    // A batch's gathered node rows and its sums (local_frame.cc), each
    // with room to align its rows to 64 bytes.
    std::vector<double> local, sums;
    Eigen::MatrixXd dx, dy, dz, yx, yy, yz;  // 64 x batch columns
    Eigen::MatrixXf fx, fy, fz;              // dhat rounded (float products)
    double energy = 0;
  };
  // Forces with the matrices `packed` (packed_, packed_f_ or double copies
  // of packed_f_'s entries).
  template <typename KSet>
  double RunForces(const Points& d, Points& g, const KSet& packed);
  // One part's batches, dhat columns and products in precision T.
  template <typename T, typename KSet>
  void RunBatches(int part, const Points& d, const KSet& packed, Workspace& w);

  const ElementLayout& layout_;
  WorkerPool* pool_;
  DeformationMeasure measure_;
  int32_t num_nodes_;
  // packed_[kind][group][axis]: n x n, packed for the batched products
  // (panel_product.h); empty with float products.
  std::array<std::vector<std::array<PackedMatrix, 3>>, 3> packed_;
  // The same rounded to float (float_products_ only).
  std::array<std::vector<std::array<PackedMatrixF, 3>>, 3> packed_f_;
  // Per cubic group with float products, its matrices' sum factorization
  // where they have one (kron_product.h; an axis-aligned box of one
  // material), used in place of packed_f_'s dense products.
  std::vector<std::optional<KroneckerStiffness>> kron_;
  bool float_products_ = false;
  // Per kind and group: pooled (ScheduleElements). Pooled cubic groups are
  // applied at their quadrature points (no matrices in packed_ /
  // packed_f_); pooled linear and pyramid groups by plain products with
  // their matrices in small_ (row-major, axis after axis; the entries of
  // packed_f_ with float products) and small_f_ (float products).
  PooledGroups pooled_;
  std::array<std::vector<std::vector<double>>, 3> small_;
  std::array<std::vector<std::vector<float>>, 3> small_f_;
  // The pooled elements and their factors.
  CubicQuadratureElements quadrature_;
  // Per element, in the schedule's order (the order the
  // batches run in, so a batch reads its frames in sequence); frames() and
  // set_frames() map them to and from element order.
  std::array<std::vector<Eigen::Quaterniond>, 3> frames_;
  // Per group, the physical gradients at the element centre, n x 3 column-major.
  std::array<std::vector<Eigen::Matrix<double, Eigen::Dynamic, 3>>, 3> centre_gradient_;
  std::vector<const Points*> part_buffers_;
  ElementSchedule schedule_;  // batches and their fixed parts
  std::vector<Workspace> work_;
  Points delta_, y_;
  Timing timing_;
  int32_t integrated_groups_ = 0;
};

}  // namespace dynsolid::models
