// A deformable subdivision solid in motion (MODEL.md sections 3-6).
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

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/points.h"
#include "solver/scene/build.h"

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
  double omega_max = 0.0;          // rad/s, from power iteration
  double stable_step = 0.0;        // 2 / omega_max, seconds
  int32_t substeps = 1;            // explicit sub-steps per scene step
  bool implicit = false;           // backward Euler (asked for, or chosen by auto)
  double build_ms = 0.0;
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
};

struct Energies {
  double kinetic = 0;   // J: 1/2 v^T Mt v with v = (p - p_prev) / h_sub
  double strain = 0;    // J: the model's internal energy at p
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

  // Advances one scene time step h. Stability guard: when the state goes
  // non-finite or the energy H = kinetic + strain + springs - external work
  // grows (a stable run only loses it), the step is rolled back to its
  // start, the explicit sub-step halved, and the step retried (reported in
  // last_step().rollbacks and rollbacks()). After kMaxHalvings failed
  // halvings the state stays at the step's start and the result is
  // FailedPrecondition saying why.
  absl::Status Step();
  static constexpr int kMaxHalvings = 6;
  // Create refuses scenes whose shared element matrices would exceed this
  // (ResourceExhausted): elements of curved meshes rarely share them.
  static constexpr double kMaxSharedMatrixBytes = 4.0 * 1024 * 1024 * 1024;

  // Overrides the sub-step count chosen from the stable-step estimate
  // (tests of the stability guard; stress cases in reports).
  void SetSubstepsForTesting(int substeps);
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
  // finite-difference checks). Does not change the solid's state.
  Points InternalControlForces(const Points& p);

  // The model's strain energy (J) at control positions p (frames found
  // afresh). Does not change the solid's state.
  double StrainEnergy(const Points& p);

  // Linear static equilibrium of the corotational model about rest under the
  // scene's constant loads and penalty springs, with fixed points held:
  // K0 u = F, K0 = A^T K A assembled in control space and solved directly
  // (sparse LDL^T). Returns the control positions rest + u; does not change
  // the solid's state. FailedPrecondition for the local-frame model or a
  // singular system (a free solid).
  absl::StatusOr<Points> SolveStaticLinear();

  // Mt x (#control by 3): the control-space mass matrix applied to x.
  Points ApplyMass(const Points& x) const;

  // Kinetic energy from the last sub-step's velocity; strain energy at p
  // (forces and energy are evaluated at the end of every sub-step).
  Energies ComputeEnergies() const;
  // Total mass from Mt (kg) and the rest volume of the elements (m^3).
  double total_mass() const { return total_mass_; }
  double rest_volume() const { return rest_volume_; }

  // Current positions of the scene's traced points, in scene order.
  std::vector<Eigen::Vector3d> TracedPositions() const;
  // The traced points for control positions p (e.g. a static solution).
  std::vector<Eigen::Vector3d> TracedPositionsAt(const Points& p) const;
  const std::vector<std::string>& traced_names() const { return traced_names_; }

  const BuildReport& build_report() const { return report_; }
  const PhaseTimes& last_phases() const { return phases_; }
  const StepStats& last_step() const { return last_step_; }

  struct Impl;

 private:
  Solid();

  scene::Discretization d_;
  std::unique_ptr<Impl> impl_;
  Points p_, p_prev_;
  double h_ = 1e-3;
  double time_ = 0.0;
  int64_t steps_ = 0;
  int64_t rollbacks_ = 0;
  double total_mass_ = 0.0, rest_volume_ = 0.0;
  std::vector<std::string> traced_names_;
  BuildReport report_;
  PhaseTimes phases_;
  StepStats last_step_;
};

}  // namespace dynsolid::solid
