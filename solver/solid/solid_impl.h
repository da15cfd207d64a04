// Private to solver/solid: the Solid's internal state (Solid::Impl) and the
// small helpers its translation units share (solid.cc: build and step;
// solid_paint.cc: material painting; solid_state.cc: save and restore;
// solid_surface.cc: the boundary surface; solid_loads.cc: loads and
// constraints; solid_drags.cc: drags and curves; solid_contact.cc: haptic
// contact; solid_pick.cc: picking; solid_remesh.cc: topology
// transfer). Nothing outside solver/solid includes it.
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "solver/common/worker_pool.h"
#include "solver/contact/obstacle_contact.h"
#include "solver/material/plasticity.h"
#include "solver/fem/node_rows.h"
#include "solver/integrators/backward_euler.h"
#include "solver/integrators/central_difference.h"
#include "solver/models/cell_corotation.h"
#include "solver/models/corotational.h"
#include "solver/models/element_blocks.h"
#include "solver/fem/shape.h"
#include "solver/models/internal_force.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/energy_ledger.h"
#include "solver/solid/load_set.h"
#include "solver/solid/probe_loads.h"
#include "solver/solid/solid.h"
#include "solver/solid/surface_pressure.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {

struct CellPartials;  // cell_assembly.h
struct CellGeometry;  // cell_assembly.h
struct CellSums;     // cell_assembly.h

using SparseMatrix = subdivision::SparseMatrix;
using Clock = std::chrono::steady_clock;

// Backward Euler's CG products run in single precision at this tolerance or
// looser. A float product errs by about 1e-6 relative (element columns and K
// rounded to float, sums of 192 terms); it only steers the CG: the
// right-hand side and the residual CG starts from (the folded element pass)
// are double, and the warm start leaves CG a correction of about 1/200 of
// the right-hand side, so the product's error reaches the true residual
// scaled down again (iterative refinement). tests/solid/solid_implicit_test
// runs it against double products.
constexpr double kSinglePrecisionCgTolerance = 1e-5;

// std::string_view as Abseil's string_view (Debian's Abseil has its own).
inline absl::string_view A(std::string_view s) { return absl::string_view(s.data(), s.size()); }

// The sum of a sparse matrix's stored values, in storage order. (Eigen's
// sum() reduces with SIMD from the first 32-byte boundary of the value
// array, which the heap places differently from run to run: its bits would
// depend on where the array lands.)
inline double SumOfValues(const SparseMatrix& m) {
  double sum = 0;
  const double* v = m.valuePtr();
  for (Eigen::Index k = 0; k < m.nonZeros(); ++k) sum += v[k];
  return sum;
}

inline double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

inline Eigen::Vector3d V(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

inline bool InShape(const Region& r, const Eigen::Vector3d& x) {
  switch (r.shape_case()) {
    case Region::kBox: {
      const Eigen::Vector3d lo = V(r.box().min()), hi = V(r.box().max());
      return (x.array() >= lo.array()).all() && (x.array() <= hi.array()).all();
    }
    case Region::kSphere:
      return (x - V(r.sphere().center())).norm() <= r.sphere().radius();
    default:
      return false;
  }
}

inline bool InRegion(const Region& r, const Eigen::Vector3d& x, int32_t control_cell) {
  if (InShape(r, x)) return true;
  for (int32_t c : r.control_cells()) {
    if (c == control_cell) return true;
  }
  return false;
}

inline models::MaterialPoint ToPoint(const Material& m) {
  const Material r = scene::ResolvedMaterial(m);
  return {r.young_modulus(), r.poisson_ratio(), r.density(), r.damping()};
}

// What depends on the material samples: rebuilt together by Create,
// PaintMaterial and RestoreState (one path).
struct MaterialBuild {
  std::shared_ptr<models::ElementLayout> layout;
  std::shared_ptr<models::InternalForceModel> model;
  models::CorotationalModel* corotational = nullptr;
  SparseMatrix mt, dt;
  bool has_damping = false;
  int64_t shared_matrix_bytes = 0, element_bytes = 0;
  double model_ms = 0, mass_ms = 0;  // BuildReport::Phases
  std::shared_ptr<const CellPartials> mass_cells;
  // solver.corotation CONTROL_CELL: the model that steps (`model` then
  // serves the stable-step estimate, contact and fields) and its cells'
  // stiffness partials (Impl::k0_cells).
  std::shared_ptr<models::CellCorotation> cell_model;
  std::shared_ptr<const CellPartials> k_cells;
  int32_t k_cells_made = -1;
  // The cells' supports and geometry keys the sums used (null: none made).
  std::shared_ptr<const CellGeometry> geometry;
};

// What a change prepared off the loop (a paint, an unfix) was made for:
// Impl::PreparedForNow() then. When any of it differs at install time, the
// change is prepared again.
struct PreparedFor {
  uint64_t material_epoch = 0;  // Impl::material_epoch
  double omega_max = 0;
  int substeps = 0;
  std::vector<int32_t> fix_count;
  bool operator==(const PreparedFor&) const = default;
};

// A paint's costly half (Solid::PreparePaint), for Solid::ApplyPaint.
class Solid::PreparedPaint {
 public:
  MaterialPaint paint;
  PreparedFor made_for;
  MaterialBuild build;
  SparseMatrix k0;  // the implicit scheme's, for build
  std::shared_ptr<const CellPartials> k0_cells;  // k0's (Impl::k0_cells)
  // Backward Euler's Setup for build at one sub-step, with k0.
  std::optional<integrators::BackwardEuler::Prepared> implicit_setup;
  // The stable step and sub-steps for build, from the solid's as they were,
  // with the Lanczos estimate done here when the bound would raise the
  // sub-steps (`estimated`).
  double omega = 0;
  int substeps = 1;
  bool estimated = false;
  // Where the prepare's time went (ms): sampling the paint and laying out
  // the new material, the model (with the per-cell partials made anew:
  // build.k_cells_made), mass, and the stable step.
  double layout_ms = 0, stable_ms = 0, total_ms = 0;
  int64_t samples_painted = 0;
  // Clay: the cells' flow laws after the paint, when it paints them.
  bool paints_flow = false;
  std::vector<material::FlowLaw> laws;
  // build.model runs on this pool until installed (then on the solid's).
  std::unique_ptr<WorkerPool> pool;
};

struct Solid::Impl {
  scene::Discretization* d = nullptr;
  // d->node_matrix in the form the per-step products stream (node_rows.h).
  fem::NodeRows node_rows;
  SolverSettings settings;
  std::unique_ptr<WorkerPool> pool;
  // Shared with a contact stiffness being built off the loop
  // (Solid::ContactCacheJob), which may outlive a material change.
  std::shared_ptr<models::ElementLayout> layout;  // the model references *layout
  std::shared_ptr<models::InternalForceModel> model;
  SparseMatrix mt, dt;
  bool has_damping = false;
  integrators::CentralDifference integrator;
  integrators::BackwardEuler implicit;
  bool use_implicit = false;
  models::CorotationalModel* corotational = nullptr;  // == model when corotational
  // solver.corotation CONTROL_CELL: steps the internal forces in control
  // space (models/cell_corotation.h) instead of `model`.
  std::shared_ptr<models::CellCorotation> cell_model;
  Points g_cells;  // its forces where only their energy is wanted
  Points x_nodes, kx_nodes;
  integrators::BackwardEuler::StiffnessOperator stiffness_op;
  // Backward Euler's folded right-hand side (the default): F - h Kt w =
  // f_ext(p) - A^T g_R(A (p + h w)) - springs at p + h w (w = v + dv0, the
  // velocity plus the CG's warm start), one element pass
  // with the frames of p (Advance). `f` then holds the external
  // forces f_ext(p) only (point forces, gravity, pressure at p). With
  // implicit_two_pass (tests: the reference path) `f` holds F as for the
  // explicit scheme and F - h Kt w takes a Kt product.
  bool implicit_two_pass = false;
  integrators::BackwardEuler::ForceAhead force_ahead;
  const Points* ahead_from = nullptr;  // p of the step in progress
  Points ahead, g_ahead;               // a = p + h w; A^T g_R(A a)
  double ahead_energy = 0;             // E_R(a), J
  double ahead_ms = 0;
  int64_t element_passes = 0, frame_passes = 0;  // counters for StepStats
  // The fixed set as the integrators see it (1: held): loads.FixedFlags()
  // as of the last ApplyFixed, install or remesh.
  std::vector<uint8_t> fixed;
  // A^T w, w_i = int mu N_i dV (= Mt 1): the control-space body force per
  // unit acceleration (the load set's gravity). Empty until needed; cleared
  // when the material changes.
  Eigen::VectorXd gravity_mass;
  const Eigen::VectorXd& GravityMass();
  // Penalty springs on control points.
  std::vector<int32_t> spring_point;
  std::vector<double> spring_k;
  Points rest_control;
  Points rest_nodes;  // A rest_control: FEM nodes at rest
  // Traced material points.
  std::vector<MaterialLocation> traced;
  double h_sub = 0;
  int substeps = 1;
  double omega_max = 0, stable_step = INFINITY;
  // The fixed set the stable-step estimate was made with: it holds for any
  // superset (constraints only lower the largest eigenvalue).
  std::vector<uint8_t> omega_fixed;
  // Per-step buffers.
  Points nodes, g, f, p_next, backup_p, backup_prev;
  double last_strain_energy = 0;
  const Solid::Surface* surface = nullptr;  // the solid's boundary surface
  std::pair<uint64_t, uint64_t> fingerprint;
  // What the fingerprint covers besides the scene (Solid::GeometryKey):
  // hashed once per build, beside its cell partials.
  std::pair<uint64_t, uint64_t> geometry_key;

  // ---- Runtime loads and constraints: a part with its own state
  // (load_set.h). Impl locates what it keeps (Locate, ControlRow,
  // SelectQuads, SelectControlPoints) and turns its lists into the forces
  // the step adds (RebuildConstantLoads, RebuildPressure).
  LoadSet loads;
  using ControlWeights = LoadSet::ControlWeights;
  using KnownPoints = LoadSet::KnownPoints;
  // The control-point weights of the material point at rest position x
  // (its element's shape values times the node matrix rows), ascending by
  // control point; taken from `known` when it has x.
  absl::StatusOr<ControlWeights> ControlRow(
      const Eigen::Vector3d& x, const KnownPoints* known = nullptr) const;
  // The same weights at a located material point.
  ControlWeights ControlRowAt(const MaterialLocation& at) const;
  // A drag or curve from its message, located on this solid (ids unset).
  absl::StatusOr<LoadSet::DragLoad> MakeDrag(const Drag& d,
                                             const KnownPoints* known = nullptr) const;
  absl::StatusOr<LoadSet::DragLoad> MakeCurve(const CurveDrag& c,
                                              const KnownPoints* known = nullptr) const;

  // ---- Haptic contact (solid_contact.cc). The probe's loads are a part
  // (probe_loads.h), added to the external forces in ControlForces and
  // ExternalForces; the carried `f` includes them (SetContactLoads patches
  // it by the change). `contact.epoch` counts changes of what the contact
  // stiffness depends on (material, fixed set); the cache is rebuilt when
  // it moved.
  struct ContactCache;  // solid_contact.cc
  // What building the contact stiffness reads: the K triplets
  // (corotational) or the internal forces at `p` (local frame).
  struct ContactInputs {
    int64_t epoch = 0;
    int64_t nc = 0;
    std::vector<uint8_t> fixed;
    SparseMatrix mt, dt;
    bool has_damping = false;
    std::vector<int32_t> spring_point;
    std::vector<double> spring_k;
    std::function<std::vector<Eigen::Triplet<double, int32_t>>()> triplets;
    std::function<Points(const Points&)> forces;
    Points p;
    double extent = 0;  // the rest control mesh's largest side
  };
  // The inputs as the solid is now, its positions `p` (forces and
  // triplets left to the caller).
  ContactInputs ContactInputsNow(const Points& p) const;
  static absl::Status BuildContactCache(const ContactInputs& in, ContactCache& cache);
  ProbeLoads probe;
  struct ContactStiffness {
    int64_t epoch = 0;
    std::shared_ptr<ContactCache> cache;
  };
  ContactStiffness contact;

  // ---- Boundary surface (quads of Solid::surface_).
  SparseMatrix surface_rows;                  // node_matrix rows of the surface vertices
  std::vector<int32_t> quad_cell;             // level-L cell of each quad
  std::vector<Eigen::Vector3d> quad_centroid; // rest centroid of the quad's face
  Points surface_rest;                        // #surface vertices x 3
  // Pressure (surface_pressure.h), a part with its own state, rebuilt from
  // the load set's pressures (RebuildPressure). has_pressure: some follower
  // load is there (pressures, drags, the environment); f_press and
  // f_press_next: their control forces at p and at the next state (for the
  // ledger's work).
  SurfacePressure pressure;
  bool has_pressure = false;
  Points f_press, f_press_next;

  // ---- The environment: the floor and obstacles (scene.environment), a
  // part with its own state (solver/contact/obstacle_contact.h); null when
  // the scene has none. Its forces are position- and velocity-dependent
  // like the pressure's, so they ride in f_press (work counted
  // trapezoidally in the ledger): PositionForces adds them.
  std::unique_ptr<contact::ObstacleContact> environment;
  // ---- Clay: plastic flow per control cell or per element (solver/
  // material/plasticity.h), a part with its own state; null when no
  // material of the scene yields. Hooked into cell_model, or the
  // per-element corotational model, whenever that changes
  // (AttachPlasticity).
  std::unique_ptr<material::Plasticity> plasticity;
  // Hooks clay into the model in use (or unhooks every model without it).
  void AttachPlasticity();
  // The flow units of the model in use (control cells or elements).
  material::Plasticity::Units PlasticUnits() const;
  // A topology edit's carry-over of clay from `old` (the solid before it;
  // `point_source` new control point -> the old one it is, -1 for a new
  // point; `cell_source` new control cell -> old, -1 new): a control cell
  // whose support is the same points keeps its offsets; an element keeps
  // its offsets when its control cell's source has an element of its kind
  // at the same place (rest centroids within a quarter of its size). The
  // control cells the edit changed start from an estimate of the old
  // plastic shape (Plasticity::EstimateChanged); elements the edit changed
  // start from the mesh's rest shape. Returns the units carried.
  int32_t CarryPlasticity(const Impl& old, const std::vector<int32_t>& point_source,
                          const std::vector<int32_t>& cell_source);
  // The scene's flow law per control cell (the material at its rest
  // centroid, as the material regions give it).
  std::vector<material::FlowLaw> SceneFlowLaws(const Scene& scene) const;
  // The parts a build makes (solid_parts.cc): clay when some material of
  // the scene yields (InvalidArgument without corotational frames), and
  // the environment over `surface` (its errors name the field); then the
  // environment's stiffness for the sub-step h / substeps, raising the
  // sub-steps where it must. Returns its mean stiffness (N/m^3, 0: none).
  absl::Status MakePlasticity(const Scene& scene);
  absl::Status MakeEnvironment(const Scene& scene, const Solid::Surface& surface);
  double CalibrateEnvironment(double h);
  // A saved state's environment and clay sections, checked against this
  // solid (nothing changes), and installed.
  absl::Status ParseParts(std::string_view environment, std::string_view clay,
                          std::vector<contact::ObstacleContact::Touch>& touches,
                          std::optional<material::Plasticity::State>& plastic) const;
  void InstallParts(std::vector<contact::ObstacleContact::Touch> touches,
                    std::optional<material::Plasticity::State> plastic);

  // pressure = the follower loads (pressures, drags) and the environment's
  // contact forces at p, with the velocity from prev over one sub-step.
  void PositionForces(const Points& p, const Points& prev, Points& pressure) {
    PressureForces(p, pressure);
    if (environment != nullptr) environment->AddForces(p, prev, h_sub, pressure);
  }

  // Shape values of a kind at (u, v, w).
  void ShapeAt(const MaterialLocation& m, std::vector<double>& n) const {
    const int nodes_per = layout->blocks[m.kind].nodes;
    n.resize(nodes_per);
    std::vector<double> dn(3 * nodes_per);
    fem::Shape(static_cast<fem::ElementKind>(m.kind), m.uvw[0], m.uvw[1], m.uvw[2], n.data(),
               dn.data());
  }

  // Where material location m is for control positions p: its element's
  // shape values over that element's node rows of A p. `shape` is scratch.
  Eigen::Vector3d PositionAt(const MaterialLocation& m, const Points& p,
                             std::vector<double>& shape) const {
    ShapeAt(m, shape);
    const int32_t* ids = layout->blocks[m.kind].element_nodes(m.element);
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (size_t k = 0; k < shape.size(); ++k) x += shape[k] * node_rows.Row(p, ids[k]);
    return x;
  }

  // The stability guard's energy account: a part (energy_ledger.h).
  EnergyLedger ledger;
  Points velocity, mass_velocity, f_next;
  bool forces_valid = false;

  void SetSubsteps(int n, double h,
                   std::optional<integrators::BackwardEuler::Prepared>* prepared = nullptr) {
    substeps = n;
    h_sub = h / n;
    if (use_implicit && prepared != nullptr && prepared->has_value() &&
        (*prepared)->h == h_sub && (*prepared)->fixed == fixed) {
      // Made off the loop for these very values (a prepared paint).
      implicit.Setup(&mt, has_damping ? &dt : nullptr, std::move(**prepared));
      prepared->reset();
    } else if (use_implicit) {
      // (The bits of Setup(h_sub, fixed) then SetStiffnessPreconditioner(k0),
      // without the column preconditioner a factor makes unneeded.)
      implicit.Setup(&mt, has_damping ? &dt : nullptr,
                     integrators::BackwardEuler::Prepare(mt, has_damping ? &dt : nullptr, h_sub,
                                                         fixed, k0.rows() > 0 ? &k0 : nullptr));
    } else if (SetupFor now{material_epoch, h_sub, fixed}; explicit_setup != now) {
      // (A restore that keeps the material, the sub-step and the fixed set,
      // as an undo of a load does, keeps the integrator's matrices and
      // preconditioner: the same bits, without refactoring them.)
      integrator.Setup(&mt, has_damping ? &dt : nullptr, h_sub, fixed,
                       settings.explicit_solve() == SolverSettings::CG
                           ? integrators::CentralDifference::Solve::kCg
                           : integrators::CentralDifference::Solve::kFactored);
      explicit_setup = std::move(now);
    }
  }
  // What the explicit integrator was last set up for (SetSubsteps).
  struct SetupFor {
    uint64_t material_epoch = 0;
    double h_sub = 0;
    std::vector<uint8_t> fixed;
    bool operator==(const SetupFor&) const = default;
  };
  std::optional<SetupFor> explicit_setup;
  // Backward Euler's operators over this solid: the linearized stiffness
  // product (stiffness_op) and the folded right-hand side (force_ahead).
  void MakeImplicitOperators();
  // Runs the sub-steps of one scene step from (p, p_prev); error when the
  // state goes non-finite or H grows (p, p_prev are then garbage).
  absl::Status Advance(Points& p, Points& p_prev, StepStats& stats, PhaseTimes& phases);

  // K0 (3 #control square, row-major), its cells' partials taken from
  // `previous` where their keys match and this build's stored in *next
  // (cell_assembly.h).
  static SparseMatrix StiffnessSparse(
      const scene::Discretization& d, const models::ElementLayout& layout,
      const models::CorotationalModel& corotational, const std::vector<int32_t>& spring_point,
      const std::vector<double>& spring_k, WorkerPool& threads,
      const CellPartials* previous = nullptr, std::shared_ptr<const CellPartials>* next = nullptr);
  // A sparse matrix's entries, row by row.
  static std::vector<Eigen::Triplet<double, int32_t>> TripletsOf(const SparseMatrix& k);
  // K0 of this solid now, as triplets.
  std::vector<Eigen::Triplet<double, int32_t>> StiffnessTriplets() const {
    return TripletsOf(StiffnessSparse(*d, *layout, *corotational, spring_point, spring_k, *pool,
                                      k0_cells.get()));
  }
  // The per-control-cell corotational model from its cells' partials (a
  // per-cell sum of StiffnessPartials).
  std::unique_ptr<models::CellCorotation> CellCorotationFrom(CellSums& sums,
                                                             WorkerPool& threads) const;
  // K0 for layout `l` and its model `m`, on `threads`.
  // `made` (optional): partials of l made already (a build's per-cell
  // corotation, MaterialBuild::k_cells), taken first.
  SparseMatrix StiffnessMatrix(const models::ElementLayout& l, const models::CorotationalModel& m,
                               WorkerPool& threads, std::shared_ptr<const CellPartials>* next,
                               const CellPartials* made = nullptr) const {
    return StiffnessSparse(*d, l, m, spring_point, spring_k, threads,
                           made != nullptr ? made : k0_cells.get(), next);
  }
  SparseMatrix k0;  // rest stiffness for the implicit preconditioner
  // The cells' partial sums of Mt (and Dt) and of K0 (cell_assembly.h),
  // for the next build of this solid or of one remeshed from it.
  std::shared_ptr<const CellPartials> mass_cells, k0_cells;
  // The control cells' supports and geometry keys (cell_assembly.h
  // CellGeometry): functions of the node matrix and the elements' nodes,
  // which a material build (a paint, a restore) does not change, so made
  // by the first build and taken by the next.
  std::shared_ptr<const CellGeometry> cell_geometry;

  // Each element's rest bounding box, by kind and element index (Locate;
  // a paint's reach). Made once, when the solid is created: its elements
  // and rest nodes never change (a topology edit makes another solid),
  // whatever material is laid out over them.
  std::array<std::vector<Eigen::AlignedBox3d>, 3> element_boxes;
  void MakeElementBoxes(const models::ElementLayout& l);
  // The material point at rest position x (rest_nodes).
  absl::StatusOr<MaterialLocation> Locate(const Eigen::Vector3d& x, bool snap) const;
  // Mt and Dt from the sums of MassPartials (dense or as triplets), lumped
  // when the settings say so.
  void ControlMatricesFrom(const CellSums& sums, bool dense, bool has_damping, SparseMatrix& mt,
                           SparseMatrix& dt) const;
  // *passes (optional): the element passes it took. With `cells` (the
  // per-control-cell corotation of m's layout) Kt is applied in control
  // space (CellCorotation::ApplyRest on cell_pool) instead of through m.
  double EstimateOmegaMax(models::InternalForceModel& m, const SparseMatrix& mass,
                          const std::vector<uint8_t>& fixed_set, int* passes = nullptr,
                          const models::CellCorotation* cells = nullptr,
                          WorkerPool* cell_pool = nullptr) const;
  // `prev`: the positions one sub-step before p (the environment's velocities).
  void ControlForces(const Points& p, const Points& prev, Points& out, PhaseTimes& phases,
                     Points& pressure);
  // out = A p (A the node matrix, as node_rows), its rows split over the
  // pool: each row's sum is taken whole by one thread, so the bits do not
  // depend on the thread count.
  void ToNodes(const Points& p, Points& out);
  // out = A^T g: A's rows in kProjectParts fixed ranges, each range's
  // product A_k^T g_k into a buffer of its own (ranges taken by whichever
  // thread is free), then the buffers added in range order: the same bits
  // whatever the thread count.
  void FromNodes(const Points& g, Points& out);
  static constexpr int kProjectParts = 8;
  std::array<Points, kProjectParts> project_parts;
  // Folded implicit path: the frames at p and out = f_ext(p) (constant loads
  // and pressure at p; no internal or spring forces); with `energy` also the
  // exact strain energy at p (one element pass more).
  void ImplicitForces(const Points& p, const Points& prev, Points& out, PhaseTimes& phases,
                      Points& pressure, bool energy);
  bool Folded() const { return use_implicit && !implicit_two_pass; }
  // out = f_ext(p): constant loads and the pressure at p (into `pressure`).
  void ExternalForces(const Points& p, const Points& prev, Points& out, Points& pressure,
                      PhaseTimes& phases);
  // A load edit (point force, pressure, gravity). The folded implicit path
  // carries only the external forces in `f`: they are recomputed at the next
  // step, no element pass (loads_changed; recomputing unchanged loads gives
  // the same bits, so the flag only saves time and need not be saved). The
  // other paths recompute all forces.
  bool loads_changed = false;
  void LoadsChanged() {
    if (Folded()) {
      loads_changed = true;
    } else {
      forces_valid = false;
    }
  }

  // Material: builds what depends on it from a layout (ResourceExhausted
  // when the element matrices would not fit), and installs a build.
  // The model, mass and damping for layout `l`. With `reuse` (a new
  // material on the same mesh: a paint, a restored state), what the current
  // build already has is taken over where its inputs are unchanged: element
  // matrices of groups with the same rest shape and stiffness samples, the
  // deformation measure, and Mt and Dt when no density or damping sample
  // changed. Each is what integrating again would give, bit for bit.
  // The model runs on `model_pool` (default: the solid's pool) until
  // set_pool moves it. `beside`: the caller's jobs that read nothing this
  // makes, each run once on a pool thread while the cells' partials are
  // made (SumByCells), else before they are summed.
  absl::StatusOr<MaterialBuild> BuildMaterial(
      std::unique_ptr<models::ElementLayout> l, bool reuse = false,
      WorkerPool* model_pool = nullptr,
      const std::vector<std::function<void()>>& beside = {}) const;
  // True when every element's density and damping samples in `l` equal the
  // current layout's.
  bool SameMassAndDamping(const models::ElementLayout& l) const;
  bool paint_reuse = true;  // tests turn it off for a from-scratch reference
  void InstallMaterial(MaterialBuild b);
  // The material the last InstallMaterial replaced, with its K0 (implicit):
  // an undo after a paint, or a redo after that undo, asks for exactly it
  // (Solid::PrepareState takes it back instead of building it again: the
  // same bits, as a build is a function of the material alone). One kept.
  struct RetiredMaterial {
    MaterialBuild build;
    SparseMatrix k0;
    std::shared_ptr<const CellPartials> k0_cells;
  };
  // The retired material when `is_it` says it is the one asked for (it is
  // then no longer kept), else none.
  std::optional<RetiredMaterial> TakeRetired(
      const std::function<bool(const models::ElementLayout&)>& is_it) const;
  // SaveState's material section (format version 5) and its checksum, for
  // material_epoch section_epoch.
  mutable std::mutex section_mu;
  mutable uint64_t section_epoch = 0;
  mutable std::shared_ptr<const std::string> section_bytes;
  mutable uint64_t section_sum = 0;
  mutable std::mutex retired_mu;
  mutable std::optional<RetiredMaterial> retired;  // guarded by retired_mu
  // Counts InstallMaterial calls: a prepared paint is for one material.
  uint64_t material_epoch = 0;
  PreparedFor PreparedForNow() const {
    return {material_epoch, omega_max, substeps, loads.fix_count()};
  }
  // Backward Euler's CG products in single precision when the tolerance
  // allows (kSinglePrecisionCgTolerance); after the model or use_implicit
  // changes.
  void ConfigureLinearized();
  bool SinglePrecisionLinearized() const;
  // A model of its own for `live` (a model of this solid) and its layout
  // `l` (kept alive by the caller), on `pool`: live's element matrices
  // taken over, the same forces. Reads only what never changes after the
  // solid is made, so it may run off the simulation thread.
  std::unique_ptr<models::InternalForceModel> ModelCopy(const models::ElementLayout& l,
                                                        const models::InternalForceModel& live,
                                                        WorkerPool& pool) const;
  bool double_cg = false;  // SetDoublePrecisionCgForTesting
  int SubstepsFor(double omega) const;
  // The fewest sub-steps the environment's contact needs (1 without one).
  int MinSubsteps() const { return environment != nullptr ? environment->min_substeps() : 1; }
  // The load set's forces from its lists (in id order), from scratch: its
  // constant forces (point forces then gravity) and the per-quad pressure.
  void RebuildConstantLoads();
  void RebuildPressure();
  void PressureForces(const Points& p, Points& out);
  // Selections of a region at rest.
  std::vector<int32_t> SelectControlPoints(const Region& r) const;
  std::vector<int32_t> SelectQuads(const Region& r) const;
  absl::Status CheckControlCells(const Region& r, std::string_view field) const;
  double SpringEnergy(const Points& p) const {
    double e = 0;
    for (size_t s = 0; s < spring_point.size(); ++s) {
      e += 0.5 * spring_k[s] * (p.row(spring_point[s]) - rest_control.row(spring_point[s])).squaredNorm();
    }
    return e;
  }
  void RebaseLedger(const Points& p, const Points& p_prev) {
    const Points v = (p - p_prev) / h_sub;
    const Points mv = mt * v;
    const double mech = 0.5 * (v.array() * mv.array()).sum() + last_strain_energy + SpringEnergy(p);
    ledger.Rebase(mech);
  }
};

// A state's parsed contents and the material it holds (Solid::PrepareState),
// for Solid::RestorePreparedAtClock.
class Solid::PreparedState {
 public:
  std::string bytes;  // kept when prepared for later (PrepareState)
  uint64_t material_epoch = 0;
  bool used = false;
  double time = 0;
  int64_t steps = 0, rollbacks = 0;
  int32_t substeps = 1;
  double omega = 0, stable = 0;
  bool forces_valid = false;
  double strain = 0;
  EnergyLedger::Values ledger;  // its rebase flag included
  Points p, p_prev, f, f_press;
  integrators::BackwardEuler::History warm;
  std::string omega_fixed_bytes;
  LoadSet loads;  // held positions included
  std::vector<contact::ObstacleContact::Touch> touches;  // the environment's
  std::optional<material::Plasticity::State> plastic;  // clay's
  models::InternalForceModel::Frames frames;
  std::optional<MaterialBuild> build;  // when the material differs
  bool taken_back = false;             // build is Impl::retired's
  SparseMatrix k0;      // with build, implicit
  std::shared_ptr<const CellPartials> k0_cells;
  std::optional<integrators::BackwardEuler::Prepared> implicit_setup;
  // build is made on this pool (the solid's may be stepping); its model
  // runs on the solid's once installed.
  std::unique_ptr<WorkerPool> pool;
};

// An unfix's decision and stable-step estimate (Solid::PrepareUnfix).
class Solid::PreparedUnfix {
 public:
  int64_t constraint_id = 0;
  PreparedFor made_for;
  bool used = false;
  // The result.
  std::vector<int32_t> count;
  std::vector<uint8_t> new_fixed;
  bool reestimate = false;
  double omega = 0;
  int substeps = 1;
};

}  // namespace dynsolid::solid
