// What dynsolid-sim writes: stats.json and the export files of a built solid.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "solver/scene/build.h"

namespace dynsolid::tools {

// stats.json: counts of the paper's Table 1 (control cells, elements by kind
// and their share of the level-L cells) plus build timings.
std::string StatsJson(const scene::Discretization& d, const scene::BuildTimings& t,
                      const std::string& origin);

// Writes DIR/stats.json, DIR/boundary.obj, DIR/boundary.ply (with a
// per-vertex `element_kind` field of the cell each boundary vertex first
// meets) and DIR/volume.vtu, positions d = node_matrix * p at rest.
// Creates DIR. Writes nothing if the surface or volume is inconsistent.
absl::Status WriteOutputs(const scene::Discretization& d, const scene::BuildTimings& t,
                          const std::string& origin, const std::string& dir);

}  // namespace dynsolid::tools
