// dynsolid-sim: builds a scene's subdivision solid offline and writes its
// statistics (stats.json), boundary surface (OBJ, PLY) and volume (.vtu).
//
//   dynsolid-sim --scene block3 --out out/block3
//   dynsolid-sim --scene scenes/chair.textproto --levels 1 --out out/chair
//   dynsolid-sim --scene part.msh --out out/part
//
// Exit codes: 0 done; 2 bad input (the message says what and where; nothing
// is written); 1 an output file could not be written.
#include <iostream>
#include <optional>
#include <string>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/tools/sim_report.h"
#include "spdlog/spdlog.h"

ABSL_FLAG(std::string, scene, "block3",
          "A built-in scene name, a scene file (.textproto) or a mesh file (.msh, .vtk)");
ABSL_FLAG(int, levels, -1, "Subdivision levels (0-4); -1 keeps the scene's");
ABSL_FLAG(int, steps, 0, "Time steps to run (the dynamics arrive with issue 3; must be 0)");
ABSL_FLAG(std::string, out, "", "Output folder (created)");

int main(int argc, char** argv) {
  absl::SetProgramUsageMessage("dynsolid-sim --scene NAME|FILE [--levels L] --out DIR");
  absl::ParseCommandLine(argc, argv);
  auto log = spdlog::default_logger();
  log->set_pattern("[%H:%M:%S.%e] [sim] %v");

  const std::string out = absl::GetFlag(FLAGS_out);
  if (out.empty()) {
    std::cerr << "dynsolid-sim: --out is required\n";
    return 2;
  }
  if (absl::GetFlag(FLAGS_steps) != 0) {
    std::cerr << "dynsolid-sim: --steps " << absl::GetFlag(FLAGS_steps)
              << ": time stepping is not available in this build yet (only --steps 0)\n";
    return 2;
  }
  std::optional<int> levels;
  if (absl::GetFlag(FLAGS_levels) >= 0) levels = absl::GetFlag(FLAGS_levels);

  absl::StatusOr<dynsolid::scene::LoadedScene> loaded =
      dynsolid::scene::LoadSceneOrMesh(absl::GetFlag(FLAGS_scene));
  if (!loaded.ok()) {
    std::cerr << "dynsolid-sim: " << loaded.status().message() << "\n";
    return 2;
  }
  dynsolid::scene::BuildTimings timings;
  absl::StatusOr<dynsolid::scene::Discretization> d = dynsolid::scene::BuildDiscretization(
      loaded->scene, loaded->base_dir, levels, &timings);
  if (!d.ok()) {
    std::cerr << "dynsolid-sim: " << loaded->origin << ": " << d.status().message() << "\n";
    return 2;
  }
  log->info("{}: {} control cells -> {} cells at level {}: {} cubic, {} linear, {} pyramid "
            "elements",
            loaded->origin, d->control().num_cells(), d->fine().num_cells(),
            d->hierarchy.levels, d->elements.num_cubic(), d->elements.num_linear(),
            d->elements.num_pyramid());
  const absl::Status written = dynsolid::tools::WriteOutputs(*d, timings, loaded->origin, out);
  if (!written.ok()) {
    std::cerr << "dynsolid-sim: " << written.message() << "\n";
    return 1;
  }
  log->info("wrote {}/stats.json, boundary.obj, boundary.ply, volume.vtu", out);
  return 0;
}
