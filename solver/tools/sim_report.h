// What dynsolid-sim writes: stats.json and the export files of a built solid.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "solver/common/stats.h"
#include "solver/scene/build.h"
#include "solver/solid/solid.h"

namespace dynsolid::tools {

// What a run of N steps measured (empty when no steps ran).
struct RunRecord {
  std::vector<double> step_ms;                 // wall time per step
  std::vector<solid::PhaseTimes> phases;       // per step
  std::vector<int32_t> cg_iterations;          // per step (summed)
  int32_t cg_max = 0;
  int64_t rollbacks = 0;                       // stability-guard rollbacks
  int32_t final_substeps = 1;
  solid::Energies energies;                    // at the end
  const solid::BuildReport* build = nullptr;
  double time_step = 0, total_mass = 0, rest_volume = 0;
  std::string model = "local_frame", integrator = "central_difference";
  // The local-frame model's element products in a step: "float" or "double".
  std::string element_products = "double";
};

// stats.json: counts of the paper's Table 1 (control cells, elements by kind
// and their share of the level-L cells), build timings and, after a run,
// ms_per_step (median), steps per second, per-phase medians (a phase the
// scene does not use is absent), CG iterations (mean, max), energies.
std::string StatsJson(const scene::Discretization& d, const scene::BuildTimings& t,
                      const std::string& origin, const RunRecord& run);


// Writes DIR/stats.json, DIR/boundary.obj, DIR/boundary.ply (with a
// per-vertex `element_kind` field of the cell each boundary vertex first
// meets) and DIR/volume.vtu, positions d = node_matrix * p at rest.
// Creates DIR. Writes nothing if the surface or volume is inconsistent.
absl::Status WriteOutputs(const scene::Discretization& d, const scene::BuildTimings& t,
                          const std::string& origin, const RunRecord& run,
                          const Points& control_positions, const std::string& dir);

// A frame of the solid at control positions p: DIR/NAME.obj and NAME.vtu.
absl::Status WriteFrame(const scene::Discretization& d, const Points& p, const std::string& dir,
                        const std::string& name);

}  // namespace dynsolid::tools
