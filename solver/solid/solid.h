// A deformable subdivision solid in motion (docs/model.md sections 3-6), with
// runtime edits for live sessions (loads, constraints, material painting),
// exact save/restore and the boundary surface for watchers. Scene items
// (loads, constraints) get ids that the runtime edits name.
//
// Built once from a scene and its discretization: element quadrature data,
// per-element material sample arrays, the internal-force model, the
// control-point-space matrices Mt = A^T M A (and Dt only when the scene has
// damping), loads and constraints. Each Step() then advances the control
// points p by the scene's fixed time step h (with automatic explicit
// sub-steps when h is above the stable step), allocating nothing.
//
// Threading: a Solid is used by one thread at a time (the simulation
// thread); const accessors may be called from it only. Results are bit
// identical for the same scene and build, whatever the thread count.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/points.h"
#include "solver/scene/build.h"
#include "solver/solid/load_bounds.h"
#include "solver/solid/saved_state.h"

namespace dynsolid::models {
struct MaterialPoint;
}  // namespace dynsolid::models

namespace dynsolid::solid {

// What was built for this scene (a scene uses only what it asks for).
struct BuildReport {
  bool damping_matrix = false;     // Dt assembled (some damping density > 0)
  int32_t cubic_groups = 0;        // distinct cubic element matrices (shared)
  int32_t linear_groups = 0;
  int32_t pyramid_groups = 0;      // 0: no pyramid kernels built
  int32_t material_arrays = 0;     // distinct per-element sample arrays
  int32_t fixed_control_points = 0;
  int32_t penalty_springs = 0;
  int32_t point_forces = 0;
  bool gravity = false;
  int64_t element_bytes = 0;       // per-element storage beyond the mesh
  int64_t shared_matrix_bytes = 0; // the shared element matrices
  // The node matrix A as the per-step products stream it (node_rows.h):
  // its bytes, and whether its values are stored as floats (exactly).
  int64_t node_matrix_bytes = 0;
  bool node_matrix_float_values = false;
  // Cubic elements whose products run sum-factorized (local-frame model
  // with float products; models/kron_product.h).
  int64_t factorized_elements = 0;
  // Cubic elements applied at their quadrature points (models/cubic_quadrature.h;
  // 0 when corotated per control cell: no element products are made).
  int64_t quadrature_elements = 0;
  // solver.corotation CONTROL_CELL (models/cell_corotation.h): the control
  // cells it steps, their distinct stiffness matrices and those matrices'
  // bytes (all 0 otherwise).
  int32_t corotated_cells = 0;
  int32_t cell_matrices = 0;
  int64_t cell_matrix_bytes = 0;
  // How the local-frame measure runs its quadrilateral faces
  // (models::QuadPathName: "avx512", "avx2", "per-corner"); empty for the
  // corotational model.
  std::string measure_quad_path;
  double omega_max = 0.0;          // rad/s, Lanczos estimate (solid.cc EstimateOmegaMax)
  double stable_step = 0.0;        // 2 / omega_max, seconds
  int32_t stable_step_passes = 0;  // element passes the estimate took (Lanczos steps)
  int32_t substeps = 1;            // explicit sub-steps per scene step
  bool implicit = false;           // backward Euler (asked for, or chosen by auto)
  // Backward Euler's CG applies the element matrices in single precision
  // (cg_tolerance >= kSinglePrecisionCgTolerance; see solid.cc).
  bool single_precision_cg = false;
  double build_ms = 0.0;
  // The environment's contact stiffness, N/m per m^2 of surface
  // (contact/obstacle_contact.h Calibrate); 0: no floor or obstacles.
  double contact_kappa = 0.0;
  // Distinct control-cell partial sums of Mt (and Dt) and of K0 this build
  // made rather than took from the solid it was remeshed from
  // (cell_assembly.h), of `control_cell_partials`; -1: too large to keep.
  int32_t mass_cells_made = 0, k0_cells_made = 0, control_cell_partials = 0;
  // Restores (undo, redo) that took back the material the solid had just
  // before its current one instead of building it again.
  int64_t materials_taken_back = 0;
  // Where build_ms went (milliseconds): the element layout (shapes grouped,
  // materials sampled), the force model, the mass and damping in control
  // space, the boundary surface (with the element boxes: made on a pool
  // thread beside the model's cell partials, so `model` includes its wall
  // time where there are partials to make), the stable-step estimate,
  // backward Euler's K0 (0 when explicit).
  struct Phases {
    double layout = 0, model = 0, mass = 0, surface = 0, stable_step = 0, k0 = 0;
  } phases;
};

// Wall time of the phases of the last step, milliseconds; a phase the scene
// does not use stays at -1 (absent).
struct PhaseTimes {
  double nodes = -1;       // d = A p
  double measure = -1;     // local-frame deformation measure R(d)
  double stiffness = -1;   // element forces R_e K_i dhat
  double project = -1;     // A^T (f - g)
  double loads = -1;       // external forces and penalty springs
  double damping = -1;     // Dt terms (folded into the solve; kept for models that split them)
  double solve = -1;       // conjugate gradient
};

struct StepStats {
  int32_t substeps = 0;
  int32_t rollbacks = 0;           // stability-guard rollbacks in this step
  int32_t cg_iterations = 0;       // summed over sub-steps and components
  int32_t cg_max_iterations = 0;   // largest single solve
  double cg_relative_residual = 0; // largest at exit
  // Element product passes (each a K product over every element: internal
  // forces, Kt products of CG and of a right-hand side, the folded
  // right-hand side), summed over sub-steps and retries; frame-only passes
  // (the implicit step's UpdateFrames) apart.
  int32_t element_passes = 0;
  int32_t frame_passes = 0;
  // Backward Euler steps whose CG warm start was checked against the exact
  // right-hand side (one Kt product each; see integrators/backward_euler.h).
  int32_t warm_start_rechecks = 0;
};

struct Energies {
  double kinetic = 0;   // J: 1/2 v^T Mt v with v = (p - p_prev) / h_sub
  double strain = 0;    // J: the model's internal energy at p
  double springs = 0;   // J: the penalty springs' energy at p (1/2 k |p - anchor|^2)
};

class Solid {
 public:
  Solid(const Solid&) = delete;
  Solid& operator=(const Solid&) = delete;
  ~Solid();

  // Builds everything the scene asks for. InvalidArgument names the scene
  // field at fault (a traced point outside the solid, a bad material...).
  static absl::StatusOr<std::unique_ptr<Solid>> Create(const Scene& scene,
                                                       scene::Discretization discretization);
  // The same with the number of threads that step it (1-8; 0: BuildThreads(),
  // the hardware's or DYNSOLID_THREADS). Results are bit-identical for any
  // number: a server picks it by how many sessions share its cores.
  static absl::StatusOr<std::unique_ptr<Solid>> Create(const Scene& scene,
                                                       scene::Discretization discretization,
                                                       int threads);

  // Advances one scene time step h. Stability guard: when the state goes
  // non-finite, the energy H = kinetic + strain + springs - external work
  // grows (a stable run only loses it), or the control points spread over
  // more than 10 times their rest extent (load_bounds.h CheckExtent: a
  // blow-up a follower pressure pays for), the step is rolled back to its
  // start, the explicit sub-step halved, and the step retried (reported in
  // last_step().rollbacks and rollbacks()). After kMaxHalvings failed
  // halvings the state stays at the step's start and the result is
  // FailedPrecondition "step N failed: why" (N = steps() + 1).
  absl::Status Step();
  static constexpr int kMaxHalvings = 6;
  // Create refuses scenes whose element matrices would exceed this
  // (ResourceExhausted): elements of curved meshes rarely share them (cubic
  // elements at their quadrature points count their factors instead).
  static constexpr double kMaxSharedMatrixBytes = 4.0 * 1024 * 1024 * 1024;
  // Tests: the limit Create checks instead (0 restores kMaxSharedMatrixBytes).
  static void SetMaxElementBytesForTesting(double bytes);

  // Overrides the sub-step count chosen from the stable-step estimate
  // (tests of the stability guard; stress cases in reports).
  void SetSubstepsForTesting(int substeps);
  // Off: a paint or restore integrates every element matrix and assembles
  // Mt and Dt afresh (the reference the reuse path is tested against).
  void SetPaintReuseForTesting(bool reuse);
  // Backward Euler's right-hand side F - h Kt v: folded into one element
  // pass (default; the frames of p held, the force at p + h v) or, with
  // true, the two-pass reference (F at p, then a Kt product). Both solve the
  // same system; results agree to the CG tolerance.
  void SetImplicitTwoPassForTesting(bool two_pass);
  // Backward Euler's CG products in double even where the tolerance would
  // run them in single precision (tests: the reference).
  void SetDoublePrecisionCgForTesting();
  int64_t rollbacks() const { return rollbacks_; }

  double time() const { return time_; }
  int64_t steps() const { return steps_; }
  double time_step() const { return h_; }

  const Points& control_positions() const { return p_; }  // #control by 3
  Points NodePositions() const;                            // #nodes by 3: A p
  const scene::Discretization& discretization() const { return d_; }

  // Puts the solid at control positions p at rest (zero velocity), e.g. a
  // deflected shape to release. Fixed points keep their rest positions.
  void SetAtRest(const Points& p);

  // A^T g(A p): the model's internal forces on the control points at
  // control positions p (#control by 3), frames found afresh (tests, reports,
  // finite-difference checks), with double-precision element products
  // whatever solver.element_products says. Does not change the solid's state.
  Points InternalControlForces(const Points& p);

  // The model's strain energy (J) at control positions p (frames found
  // afresh; double-precision products). Does not change the solid's state.
  double StrainEnergy(const Points& p);

  // Linear static equilibrium of the corotational model about rest under the
  // constant loads (point forces, gravity; not the follower pressures) and
  // penalty springs, with fixed points held at rest:
  // K0 u = F, K0 = A^T K A assembled in control space and solved directly
  // (sparse LDL^T). Returns the control positions rest + u; does not change
  // the solid's state. FailedPrecondition for the local-frame model or a
  // singular system (a free solid).
  absl::StatusOr<Points> SolveStaticLinear();

  // Mt x (#control by 3): the control-space mass matrix applied to x.
  Points ApplyMass(const Points& x) const;

  // Kinetic energy from the last sub-step's velocity; strain energy at p
  // (forces and energy are evaluated at the end of every sub-step). With
  // backward Euler the strain energy of p is measured in the element frames
  // its step was linearized in (those of the step's start; exact from the
  // step's own products, no extra element pass; StrainEnergy(p) takes p's
  // own frames: they differ by the frames' change over one step).
  Energies ComputeEnergies() const;
  // Total mass from Mt (kg) and the rest volume of the elements (m^3).
  // The scale loads are checked against (load_bounds.h): size, mean
  // modulus, density, mass.
  LoadScale load_scale() const;
  double total_mass() const { return total_mass_; }
  double rest_volume() const { return rest_volume_; }

  // Current positions of the scene's traced points, in scene order.
  std::vector<Eigen::Vector3d> TracedPositions() const;
  // The traced points for control positions p (e.g. a static solution).
  std::vector<Eigen::Vector3d> TracedPositionsAt(const Points& p) const;
  const std::vector<std::string>& traced_names() const { return traced_names_; }

  // ---- Runtime edits (live sessions). Called by the simulation thread
  // between Step() calls. Each validates everything first and, on error,
  // returns InvalidArgument (NotFound for an unknown id) naming the field
  // and the reason, leaving the state bit-identical (SaveState() bytes and
  // every later step). Results are deterministic: the same calls at the
  // same steps give the same bits, for any thread count.
  //
  // Ids of loads and constraints come from one counter per solid, start at
  // 1, are never reused, and are assigned in call order. Create gives the
  // scene's own items ids first: loads.point_forces in order, then
  // loads.pressures, then constraints.fixed (so RemoveLoad/Unfix can also
  // remove those). Gravity is not an id item: SetGravity replaces it.
  //
  // After any edit the forces at the current state are recomputed by the
  // next Step(), and the stability guard's energy ledger is re-baselined at
  // the current state (its kinetic + strain + spring energy, external work
  // zero) whenever the configuration changes (fix, unfix, paint), so a
  // legitimate edit never triggers a rollback.

  // A constant force (newtons) at the material point whose rest position is
  // f.position (found like the scene's point forces, docs/model.md 6). Fields:
  // "point_force.position.x must be finite ...", "point_force.position:
  // point (...) is not inside the solid at rest".
  absl::StatusOr<int64_t> AddPointForce(const PointForce& f);
  // A follower pressure (scene.proto Pressure: positive inflates) on the
  // level-L boundary faces whose rest centroid lies in p.region (or whose
  // cell belongs to region.control_cells). InvalidArgument when it selects
  // no face ("pressure.region selects no boundary face ..."). Its work is
  // counted in the energy ledger (trapezoidal f . dp per sub-step).
  absl::StatusOr<int64_t> AddPressure(const Pressure& p);
  // Gravity acceleration (m/s^2), replacing the scene's; zero removes it.
  absl::Status SetGravity(const Vec3& g);
  // Removes a point force, pressure, drag or curve. NotFound naming the id
  // otherwise.
  absl::Status RemoveLoad(int64_t id);

  // A drag (scene.proto Drag): a spring of d.stiffness N/m from the
  // material point whose rest position is d.material_point to d.target,
  // evaluated in every force evaluation like the follower pressure (its
  // work counted in the energy ledger the same way). Returns its load id.
  // InvalidArgument naming the field: a point outside the solid at rest, a
  // stiffness <= 0 or above kMaxDragStiffness.
  absl::StatusOr<int64_t> AddDrag(const Drag& d);
  // A curve manipulation (scene.proto CurveDrag): its sampled material
  // points each tied by a drag spring to the target polyline. Returns its
  // load id. InvalidArgument naming the field (fewer than 2 points, counts
  // that differ, a sample outside the solid...).
  absl::StatusOr<int64_t> AddCurveDrag(const CurveDrag& c);
  // New targets: one for a drag, the target polyline (as many points as the
  // curve was started with) for a curve. NotFound for an unknown id,
  // InvalidArgument for a wrong count or a non-finite target.
  absl::Status MoveDrag(int64_t id, const std::vector<Eigen::Vector3d>& targets);
  static constexpr double kMaxDragStiffness = 1e9;  // N/m
  // Current positions of the material points whose rest positions are
  // `rest` (e.g. a drag's grip); InvalidArgument naming the index of a
  // point outside the solid at rest.
  absl::StatusOr<std::vector<Eigen::Vector3d>> MaterialPositions(
      const std::vector<Eigen::Vector3d>& rest) const;

  // Holds the control points whose REST position lies in r (or that belong
  // to r.control_cells) at their CURRENT positions with zero velocity; they
  // leave the unknowns (the reduced system and its preconditioners are
  // rebuilt). InvalidArgument when r selects no control point. A point held
  // by several constraints is free again when the last one is removed.
  absl::StatusOr<int64_t> FixRegion(const Region& r);
  // Removes a fixed-region constraint; NotFound naming the id otherwise.
  // Freed points start with zero velocity.
  absl::Status Unfix(int64_t constraint_id);
  // Unfix in two halves, like PreparePaint and ApplyPaint below: the
  // stable-step estimate an unfix may need (Lanczos, 8-32 element passes)
  // runs in PrepareUnfix on a model of its own, off the simulation
  // thread; ApplyUnfix installs it (prepared again if the solid changed
  // since).
  class PreparedUnfix;
  absl::StatusOr<std::shared_ptr<PreparedUnfix>> PrepareUnfix(int64_t constraint_id) const;
  absl::Status ApplyUnfix(PreparedUnfix& prepared);

  // Paints material samples (scene.proto MaterialPaint: falloff, blending
  // and unset fields are documented there) and rebuilds what depends on the
  // material through the same path Create uses: element layout and groups,
  // the model's shared matrices (element frames carried over), Mt (and Dt
  // when some damping > 0), gravity loads, the stable-step estimate and
  // sub-step count, the preconditioners. The velocity is kept.
  // The stable step: omega'^2 <= omega^2 r / m, r the largest ratio of the
  // painted samples' stiffness eigenvalues (3 lambda + 2 mu, lambda + 2 mu,
  // mu) and m the smallest density ratio; when that bound keeps the sub-step
  // count it is used as is, otherwise omega is estimated afresh (power
  // iteration). Sub-steps never drop on a paint.
  // InvalidArgument when no sample lies in the region or the painted solid
  // would need more than solver.max_substeps explicit sub-steps;
  // ResourceExhausted when its element matrices would exceed
  // kMaxSharedMatrixBytes. Cost: a rebuild of everything material-dependent
  // (bench/paint_bench: block3 51 ms, block4 with corotational + backward
  // Euler 0.9 s), dominated by the element matrices of the new groups (a
  // smooth falloff gives most touched elements their own sample array) and,
  // when the sub-steps must grow, the stable-step estimate. All of it but
  // about a millisecond of installing can be done off the simulation
  // thread: PreparePaint below.
  absl::Status PaintMaterial(const MaterialPaint& paint);

  // PaintMaterial in two halves, so that a server can build a paint off
  // the simulation thread (PaintMaterial is exactly PreparePaint, then
  // ApplyPaint: the same bits either way).
  //
  // PreparePaint does the costly part: the new element layout, the model
  // with its element matrices, mass and damping, the stable step (the power
  // iteration, when the bound would raise the sub-steps, on the new model's
  // own thread pool), the implicit scheme's K0 and factors. It reads only
  // what stepping leaves alone, so it may run on another thread while Step
  // runs; no other call that changes the solid may run meanwhile. Its
  // errors are PaintMaterial's.
  //
  // ApplyPaint installs it at a step boundary: frames carried over, the
  // stable step and sub-steps, the constant loads. A paint prepared before
  // the material, stable step or fixed set changed is prepared again here.
  // On error nothing changed.
  class PreparedPaint;
  absl::StatusOr<std::shared_ptr<PreparedPaint>> PreparePaint(const MaterialPaint& paint) const;
  absl::Status ApplyPaint(PreparedPaint& prepared);
  // Where a prepared paint's time went, ms (for benchmarks): sampling the
  // paint and laying out the new material; the model (with the per-cell
  // partials it made anew); mass; the stable step; the whole prepare.
  struct PaintPhases {
    double layout = 0, model = 0, mass = 0, stable = 0, total = 0;
    int32_t cells_made = -1;
    int64_t samples_painted = 0;
  };
  static PaintPhases PhasesOf(const PreparedPaint& prepared);

  // Ids of the active point forces, pressures and fixed-region constraints,
  // ascending.
  std::vector<int64_t> load_ids() const;
  std::vector<int64_t> constraint_ids() const;
  Eigen::Vector3d gravity() const;

  // The active loads and constraints as they are now, ascending by id (the
  // scene's own included: they have the first ids). Read-only, for
  // inspection (a viewer draws them). Contact loads (SetContactLoads) are
  // not id items and are not listed.
  struct LoadInfo {
    enum class Kind { kPointForce, kPressure, kDrag, kCurve };
    int64_t id = 0;
    Kind kind = Kind::kPointForce;
    // Rest positions of the load's material points, metres: a point
    // force's (PointForce.position) or a drag's one point; a curve's
    // samples (the points its springs hold: evenly spaced by arc length
    // along its material polyline, the first and last at its ends); none
    // for a pressure.
    std::vector<Eigen::Vector3d> material_points;
    // Where those points are now (at the current control positions); a
    // point force snapped to a quadrature point (solver.
    // snap_forces_to_quadrature): where it acts.
    std::vector<Eigen::Vector3d> positions;
    // A drag's target, or the target of each curve sample (from the
    // latest target polyline), metres; same order as material_points.
    std::vector<Eigen::Vector3d> targets;
    Eigen::Vector3d force = Eigen::Vector3d::Zero();  // a point force, newtons
    // A pressure: pascals, the region it was given and the surface quads
    // (Surface::quads) it acts on, ascending.
    double pascals = 0;
    Region region;
    std::vector<int32_t> quads;
    double stiffness = 0;  // a drag's or curve's spring, N/m
    // A curve as it was started, with its latest target polyline (what
    // MoveDrag takes).
    CurveDrag curve;
  };
  std::vector<LoadInfo> ActiveLoads() const;
  struct ConstraintInfo {
    int64_t id = 0;
    Region region;                        // as given to FixRegion (or the scene)
    std::vector<int32_t> control_points;  // the control points it holds, ascending
  };
  std::vector<ConstraintInfo> ActiveConstraints() const;

  // ---- Exact state. SaveState() captures everything that influences
  // future steps: p, p_prev, time, steps, sub-step count and stable-step
  // estimate, rollback counter, the forces and energy carried to the next
  // step, the energy ledger, the element frames (warm starts), loads,
  // constraints and held positions, material samples, the id counter, and
  // backward Euler's CG warm start (the last step's velocity change). (The
  // explicit scheme's CG keeps no state: it is warm-started from p, p_prev.)
  // RestoreState() into a Solid freshly Created from the SAME scene and
  // discretization continues bit-identically. Format: "DSOLIDST", format
  // version (kStateFormatVersion), a 128-bit fingerprint of the scene and
  // discretization, the payload, a 64-bit checksum; little-endian doubles.
  // Errors (the state is then unchanged): InvalidArgument for another
  // format, version or scene/discretization (fingerprint mismatch);
  // DataLoss for truncated or corrupted bytes.
  // 3: drags and curves; 4: a word-wise checksum; 5: the material samples
  // last, in a section whose checksum the saving solid keeps while its
  // material is unchanged; 6: the environment's contacts (floor and
  // obstacles) after the drags (versions 3 to 5 still read).
  static constexpr uint32_t kStateFormatVersion = 6;
  std::string SaveState() const;
  // The same in two parts (saved_state.h), the material section shared
  // with every other state saved while the material is unchanged: what
  // an undo history keeps. JoinState(SaveStateParts()) == SaveState().
  SavedState SaveStateParts() const;
  static std::string JoinState(const SavedState& state);
  absl::Status RestoreState(std::string_view bytes);
  // The same, but the clock reads `time` and `steps` afterwards (undo and
  // redo: the state goes back, the session's clock goes on). The state may
  // come from a solid of the same scene created at another time.
  absl::Status RestoreStateAtClock(std::string_view bytes, double time, int64_t steps);

  // RestoreState in two halves, like PreparePaint and ApplyPaint: a server
  // prepares an undo off its simulation loop. PrepareState parses and checks
  // the bytes and builds the material they hold when it differs from the
  // current one (and the implicit scheme's factors); it reads only what
  // stepping leaves alone, so it may run while Step runs, but not beside
  // another call that changes the solid. RestorePreparedAtClock installs it
  // at a step boundary (as RestoreStateAtClock; one prepared before a
  // material change is prepared again from its bytes). Same errors as
  // RestoreState, from PrepareState; the same bits as RestoreStateAtClock.
  class PreparedState;
  absl::StatusOr<std::shared_ptr<PreparedState>> PrepareState(std::string bytes) const;
  absl::Status RestorePreparedAtClock(PreparedState& state, double time, int64_t steps);

  // ---- Topology edits (solver/sculpt/ makes the new control mesh; this
  // carries the state over). The new control mesh's vertices, with, for
  // each, its CURRENT position and the old control points it comes from
  // (weights summing to 1: {old, 1} for a survivor), and for each new
  // control cell the old cell it is or was refined from (-1: new
  // material).
  struct TopologyTransfer {
    Points current;  // #new control points x 3, metres
    std::vector<std::vector<std::pair<int32_t, double>>> vertex_sources;
    std::vector<int32_t> cell_source;
    // A bake (the same topology, the rest shape moved to these control
    // positions): point forces and drags move to where their material
    // points are baked, pins keep their control points, the velocities go
    // to zero. Null for a topology edit.
    const Points* baked = nullptr;
  };
  struct TransferReport {
    std::vector<int64_t> dropped_loads, dropped_constraints;
    std::vector<std::string> dropped_traced;
    // The scene the new solid stands for: Create(scene, its discretization)
    // then RestoreState(new solid's SaveState()) gives it back bit for bit
    // (its runtime items live in the state, its materials too; its traced
    // points are the ones kept).
    Scene scene;
  };
  // A new solid built from `scene` (the edited scene: its control mesh is
  // `discretization`'s) in the state this one is in, carried over:
  // positions from transfer.current (held points where they are held),
  // velocities interpolated through vertex_sources, materials by the
  // nearest sample of the same old control cell (base material in new
  // cells), loads, drags, constraints (re-selected from their regions;
  // kept ids), gravity, traced points, clock and rollback count; what no
  // longer has a place is dropped and named in `report`. The new solid's
  // topology_version is this one's + 1; its energy ledger restarts at the
  // carried state. Errors: the scene's (InvalidArgument naming the field).
  absl::StatusOr<std::unique_ptr<Solid>> Remeshed(const Scene& scene,
                                                  scene::Discretization discretization,
                                                  const TopologyTransfer& transfer,
                                                  TransferReport* report) const;
  // Remeshed in two parts, so that a session can build the new solid while
  // this one goes on stepping:
  //  - BuildRemeshed: the new solid at rest with this solid's materials
  //    carried over (the expensive part: element matrices, mass, the stable
  //    step). Reads only what stepping does not change (the discretization,
  //    the materials, the thread count): it may run on another thread while
  //    this solid steps, but not while it is painted.
  //  - CarryOver: this solid's state (positions, velocities, loads, drags,
  //    constraints, traced points, clock) moved onto `built`. Cheap.
  // Remeshed(...) == CarryOver(BuildRemeshed(...), ...) bit for bit.
  // `baked` (a bake: the same topology, rest moved to these control
  // positions): the old elements' materials are found at their baked rest
  // nodes.
  absl::StatusOr<std::unique_ptr<Solid>> BuildRemeshed(
      const Scene& scene, scene::Discretization discretization,
      const std::vector<int32_t>& cell_source, const Points* baked = nullptr) const;
  // Whether this solid can be baked now: FailedPrecondition naming the
  // pressure that selects its faces by a box or sphere in rest coordinates.
  absl::Status CanBake() const;
  // The rest position, after a bake to control positions `baked`, of the
  // material point at rest position x now (its control row times baked).
  absl::StatusOr<Eigen::Vector3d> BakedPosition(const Eigen::Vector3d& x,
                                                const Points& baked) const;
  absl::StatusOr<std::unique_ptr<Solid>> CarryOver(std::unique_ptr<Solid> built,
                                                   const Scene& scene,
                                                   const TopologyTransfer& transfer,
                                                   TransferReport* report) const;

  // ---- Picking: the nearest hit of the ray origin + t direction (t > 0)
  // on the current boundary surface. InvalidArgument for a non-finite or
  // zero direction; nullopt for a miss.
  struct PickHit {
    int32_t quad = -1;            // surface quad (Surface::quads)
    int32_t control_cell = -1;    // control cell the quad's cell descends from
    int32_t control_face = -1;    // boundary face of that cell nearest the material point
    Eigen::Vector3d point, material_point, normal;  // current, rest, current outward unit
    double distance = 0;          // metres along the ray (direction normalized)
  };
  absl::StatusOr<std::optional<PickHit>> Pick(const Eigen::Vector3d& origin,
                                              const Eigen::Vector3d& direction) const;

  // ---- Haptic contact (docs/model.md 9; solid_contact.cc). What a haptic probe
  // needs from the solid: the closest point of the current boundary
  // surface, the solid's local response there, and a reaction load at that
  // exact material point. The surface's quads are the boundary faces of
  // level-L trilinear (or pyramid) elements, so a point (quad, u, v) with
  // x(u, v) = (1-u)(1-v) x0 + u(1-v) x1 + u v x2 + (1-u) v x3 over the
  // quad's loop is a material point of the solid, the same at rest and
  // now: its control row is sum_k N_k(u, v) A_(node k), exactly J_c.
  struct SurfacePoint {
    int32_t quad = -1;  // surface quad (Surface::quads)
    double u = 0, v = 0;
    // Current position, rest position (material point) and current outward
    // unit normal (metres).
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
    Eigen::Vector3d material_point = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    // Signed distance of the query point along the normal (negative:
    // inside), metres; 0 for SurfacePointAt.
    double distance = 0;
  };
  // The point of the current boundary surface closest to x (every quad as a
  // bilinear patch; a degenerate quad (a, b, c, c) as its triangle).
  // InvalidArgument for a non-finite x.
  absl::StatusOr<SurfacePoint> ClosestSurfacePoint(const Eigen::Vector3d& x) const;
  // The surface point (quad, u, v) at the current state. InvalidArgument
  // for a quad out of range or (u, v) outside [0, 1]^2.
  absl::StatusOr<SurfacePoint> SurfacePointAt(int32_t quad, double u, double v) const;

  // The solid's response at a surface point over a horizon tau (docs/model.md
  // 9): W = J_c S^-1 J_c^T with S = Mt / tau^2 + Dt / tau + K on the free
  // control points. K is the model's stiffness: for the corotational model
  // A^T K A at rest (the matrix its implicit step is preconditioned with,
  // penalty springs included); for the local-frame model the finite-
  // difference Jacobian of A^T g(A p) (and the springs) at the state the
  // cache was built in, one column per free control coordinate (forward
  // differences, step 1e-6 of the solid's size, symmetrized). Built on the
  // first call and again after a paint, restore, fix or unfix (or for
  // another tau: S only); each call then costs three solves with the
  // factored S. The normal answer splits exactly over the displacement
  // field u_bar of a unit normal displacement (Ritz): stiffness = mass /
  // tau^2 + damping / tau + elastic. FailedPrecondition when the
  // local-frame model has more than kMaxContactDenseDofs free coordinates.
  struct ContactResponse {
    Eigen::Matrix3d compliance = Eigen::Matrix3d::Zero();  // W, m/N
    double stiffness = 0;         // k = 1 / (n^T W n), N/m
    double damping = 0;           // u_bar^T D u_bar, N s/m
    double mass = 0;              // u_bar^T M u_bar, kg
    double elastic = 0;           // u_bar^T K u_bar, N/m
    double static_stiffness = 0;  // 1 / (n^T J_c K^-1 J_c^T n); 0 if K is singular
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();  // of the material point, m/s
    double horizon = 0;           // tau, seconds
    double build_ms = 0;          // time spent (re)building the cache in this call
  };
  // With `build_if_stale` false, a stale cache is not built here:
  // Unavailable (build it with ContactCacheJob).
  absl::StatusOr<ContactResponse> ContactResponseAt(const SurfacePoint& c, double horizon,
                                                    bool build_if_stale = true);
  static constexpr int kMaxContactDenseDofs = 3000;

  // The contact stiffness behind ContactResponseAt, built off the
  // simulation thread (a server's probes; building it on the loop holds the
  // loop for the local-frame model's finite-difference columns: 0.2 s on
  // block3, seconds on an edited solid).
  // ContactCacheStale: ContactResponseAt would have to build it first.
  // ContactCacheJob (on the simulation thread) copies what the build reads
  // and returns the build, to run on any thread while this solid steps and
  // changes, as long as the solid lives; the local-frame columns use a model
  // of the job's own. InstallContactCache takes its result when it is still
  // for this solid's material and fixed set, and says whether it did.
  class PreparedContact;
  bool ContactCacheStale() const;
  // Changes with the material and the fixed set (a cache is for one).
  int64_t contact_epoch() const;
  std::function<absl::StatusOr<std::shared_ptr<PreparedContact>>()> ContactCacheJob() const;
  bool InstallContactCache(std::shared_ptr<PreparedContact> prepared);

  // Contact loads: constant forces (newtons) at surface material points,
  // acting in every force evaluation of the following steps until replaced
  // (like a point force; their work is counted in the energy ledger). Each
  // call replaces the whole set; an empty set removes them. Not part of the
  // saved state (a probe's real-time input: SaveState leaves them out and
  // RestoreState clears them). InvalidArgument naming the index for a bad
  // quad, (u, v) or a non-finite force; nothing changes then.
  struct ContactLoad {
    int32_t quad = -1;
    double u = 0, v = 0;
    Eigen::Vector3d force = Eigen::Vector3d::Zero();
  };
  absl::Status SetContactLoads(const std::vector<ContactLoad>& loads);
  bool has_contact_loads() const;

  // ---- Boundary surface for watchers (docs/model.md 7): the level-L boundary
  // faces. Topology is fixed until a topology edit; topology_version()
  // counts those (Remeshed gives the new solid this one's + 1).
  struct Surface {
    // Outward quads over the surface vertices. A level-0 triangle is a
    // degenerate quad (a, b, c, c); larger level-0 polygons are fanned into
    // such quads and triangles (after one level every face is a quad).
    std::vector<std::array<int32_t, 4>> quads;
    std::vector<int32_t> nodes;  // surface vertex -> fine-mesh node (= level-L vertex)
  };
  const Surface& BoundarySurface() const { return surface_; }
  int64_t topology_version() const { return topology_version_; }
  // Sets it (a session that swaps solids, e.g. undoing a topology edit,
  // keeps counting so that watchers see a new topology).
  void set_topology_version(int64_t v) { topology_version_ = v; }
  // The number of threads that step it (Create's `threads`, resolved).
  int threads() const;
  // #surface vertices by 3 at the current p: only the surface rows of A.
  Points SurfacePositions() const;
  // Per surface vertex:
  //  displacement: |x - X| (metres), current against rest;
  //  strain: the largest engineering strain |l / l0 - 1| over the surface
  //    edges and quad diagonals at the vertex (membrane stretch and shear of
  //    the surface, dimensionless);
  //  stiffness: Young's modulus (Pa), the mean over the quadrature points
  //    of the elements of the boundary cells around the vertex;
  //  mass: the mass density (kg/m^3), the same mean (it shows painted
  //    densities as stiffness shows painted moduli).
  struct SurfaceFields {
    std::vector<float> displacement, strain, stiffness, mass;
  };
  SurfaceFields ComputeSurfaceFields() const;
  // The axis-aligned box of the current surface positions (metres).
  struct Bounds {
    Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  };
  Bounds SurfaceBounds() const;

  // Clay (material/plasticity.h): the control cells whose material yields,
  // those that have yielded, the plastic dissipation so far (J) and the
  // largest accumulated plastic strain. All zero without a yielding material.
  struct PlasticStats {
    int32_t cells = 0, yielded = 0;
    double dissipation = 0, max_strain = 0;
  };
  PlasticStats plastic_stats() const;
  // The design's own state (scene.proto Design): every element's material
  // samples as painted and the clay's flow laws, plastic offsets and
  // strain. A scene of this solid's control mesh (at its rest shape) and
  // subdivision with this as its `design` creates a solid with the same
  // samples and clay state, bit for bit (the export's "save as",
  // sculpt/design_scene.h). Its dissipation history is not kept.
  Design SaveDesign() const;
  // The environment (floor, obstacles): surface vertices in contact now and
  // the deepest of them (metres below the plane it entered by).
  struct ContactStats {
    int32_t touching = 0;
    double max_depth = 0;
  };
  ContactStats contact_stats() const;

  const BuildReport& build_report() const { return report_; }
  const PhaseTimes& last_phases() const { return phases_; }
  const StepStats& last_step() const { return last_step_; }

  struct Impl;

 private:
  Solid();
  void ReportMaterial();
  void BuildSurface();
  // The scene's hash with the geometry key (its rest positions, node
  // matrix and elements' nodes: Impl::geometry_key, made by the build).
  std::pair<uint64_t, uint64_t> Fingerprint(const Scene& scene) const;
  std::pair<uint64_t, uint64_t> GeometryKey() const;
  // `clock`: the time and steps to set instead of the saved ones.
  absl::Status Restore(std::string_view bytes, const std::pair<double, int64_t>* clock);
  absl::StatusOr<std::shared_ptr<PreparedState>> PrepareStateView(std::string_view bytes) const;
  absl::Status Install(PreparedState& state, const std::pair<double, int64_t>* clock);
  // Create with materials from `whole` (whole elements' arrays, when it has
  // them) and `sampler` instead of the scene's, and the
  // cell partials of `carried`'s matrices (cell_assembly.h) where their
  // cells are unchanged (Remeshed; null: none). A solid built with
  // `carried` is for CarryOver, which sets its integrators up: it must
  // not step before.
  static absl::StatusOr<std::unique_ptr<Solid>> CreateWith(
      const Scene& scene, scene::Discretization discretization, int threads,
      const std::function<models::MaterialPoint(const Eigen::Vector3d&, int32_t)>* sampler,
      const Solid* carried = nullptr,
      const std::function<const std::vector<models::MaterialPoint>*(
          int, const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>&, int32_t)>* whole =
          nullptr);  // models::ElementMaterials
  // CreateWith's phases, in order (solid_build.cc).
  class Builder;
  // Makes impl_->fixed follow the load set's fix counts and re-sets the
  // integrators up.
  void ApplyFixed();

  scene::Discretization d_;
  std::unique_ptr<Impl> impl_;
  Points p_, p_prev_;
  double h_ = 1e-3;
  double time_ = 0.0;
  int64_t steps_ = 0;
  int64_t rollbacks_ = 0;
  double total_mass_ = 0.0, rest_volume_ = 0.0;
  std::vector<std::string> traced_names_;
  Surface surface_;
  int64_t topology_version_ = 0;
  BuildReport report_;
  PhaseTimes phases_;
  StepStats last_step_;
};

}  // namespace dynsolid::solid
