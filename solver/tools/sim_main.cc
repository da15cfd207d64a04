// dynsolid-sim: builds a scene's subdivision solid offline and writes its
// statistics (stats.json), boundary surface (OBJ, PLY) and volume (.vtu).
//
//   dynsolid-sim --scene block3 --out out/block3
//   dynsolid-sim --scene scenes/chair.textproto --levels 1 --out out/chair
//   dynsolid-sim --scene part.msh --out out/part
//   dynsolid-sim --scene beam --steps 2000 --frames 100 --out out/beam
//
// With --steps N > 0 the solid moves: DIR/trace.csv gets the time and the
// position of every traced point per step, DIR/frames/frame_NNNNNN.{obj,vtu}
// are written every --frames K steps (0: none), and stats.json gains the
// step timings, CG iterations and energies.
//
// Exit codes: 0 done; 2 bad input (the message says what and where; nothing
// is written); 1 an output file could not be written.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "cmdline/cmdline.h"
#include "solver/solid/solid.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/tools/sim_report.h"
#include "spdlog/spdlog.h"

ABSL_FLAG(std::string, scene, "block3",
          "A built-in scene name, a scene file (.textproto) or a mesh file (.msh, .vtk)");
ABSL_FLAG(int, levels, -1, "Subdivision levels (0-4); -1 keeps the scene's");
ABSL_FLAG(int, steps, 0, "Time steps to run (0: build and export only)");
ABSL_FLAG(int, frames, 0, "Write a frame (OBJ + .vtu) every K steps (0: none)");
ABSL_FLAG(std::string, out, "", "Output folder (created)");

int main(int argc, char** argv) {
  dynsolid::cmdline::ParseCommandLine(
      argc, argv, "dynsolid-sim --scene NAME|FILE [--levels L] --out DIR", __FILE__);
  auto log = spdlog::default_logger();
  log->set_pattern("[%H:%M:%S.%e] [sim] %v");

  const std::string out = absl::GetFlag(FLAGS_out);
  if (out.empty()) {
    std::cerr << "dynsolid-sim: --out is required\n";
    return 2;
  }
  const int steps = absl::GetFlag(FLAGS_steps);
  const int frames = absl::GetFlag(FLAGS_frames);
  if (steps < 0 || frames < 0) {
    std::cerr << "dynsolid-sim: --steps and --frames must be >= 0\n";
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
  dynsolid::tools::RunRecord run;
  dynsolid::Points control = d->control().positions();
  std::string trace;
  if (steps > 0) {
    absl::StatusOr<std::unique_ptr<dynsolid::solid::Solid>> solid =
        dynsolid::solid::Solid::Create(loaded->scene, *d);
    if (!solid.ok()) {
      std::cerr << "dynsolid-sim: " << loaded->origin << ": " << solid.status().message() << "\n";
      return 2;
    }
    dynsolid::solid::Solid& s = **solid;
    const dynsolid::solid::BuildReport rep_at_build = s.build_report();
    const auto& rep = rep_at_build;
    log->info("solid built in {:.0f} ms: omega_max {:.4g} rad/s, stable step {:.4g} s, {} "
              "sub-step(s) of h = {} s",
              rep.build_ms, rep.omega_max, rep.stable_step, rep.substeps, s.time_step());
    trace = "step,time";
    for (const std::string& name : s.traced_names()) {
      trace += absl::StrCat(",", name, "_x,", name, "_y,", name, "_z");
    }
    trace += "\n";
    auto trace_row = [&] {
      absl::StrAppend(&trace, s.steps(), ",", absl::StrFormat("%.9g", s.time()));
      for (const Eigen::Vector3d& x : s.TracedPositions()) {
        absl::StrAppend(&trace, absl::StrFormat(",%.12g,%.12g,%.12g", x.x(), x.y(), x.z()));
      }
      trace += "\n";
    };
    trace_row();
    std::error_code ec;
    if (frames > 0) std::filesystem::create_directories(out + "/frames", ec);
    for (int i = 0; i < steps; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      const absl::Status st = s.Step();
      run.step_ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      if (!st.ok()) {
        std::cerr << "dynsolid-sim: " << st.message() << "\n";
        return 1;
      }
      run.phases.push_back(s.last_phases());
      run.cg_iterations.push_back(s.last_step().cg_iterations);
      run.cg_max = std::max(run.cg_max, s.last_step().cg_max_iterations);
      trace_row();
      if (frames > 0 && s.steps() % frames == 0) {
        const absl::Status w = dynsolid::tools::WriteFrame(
            s.discretization(), s.control_positions(), out + "/frames",
            absl::StrFormat("frame_%06d", s.steps()));
        if (!w.ok()) {
          std::cerr << "dynsolid-sim: " << w.message() << "\n";
          return 1;
        }
      }
    }
    run.energies = s.ComputeEnergies();
    run.rollbacks = s.rollbacks();
    run.final_substeps = s.build_report().substeps;
    run.build = &rep_at_build;
    run.time_step = s.time_step();
    run.integrator = rep_at_build.implicit ? "backward_euler" : "central_difference";
    run.model = dynsolid::scene::ModelName(loaded->scene.solver());
    run.element_products =
        run.model == "local_frame" && dynsolid::scene::ResolvedSolverSettings(loaded->scene)
                                              .element_products() == dynsolid::SolverSettings::FLOAT
            ? "float"
            : "double";
    run.total_mass = s.total_mass();
    run.rest_volume = s.rest_volume();
    control = s.control_positions();
    const double ms = dynsolid::tools::Median(run.step_ms);
    log->info("{} steps: median {:.3f} ms per step ({:.0f} steps/s), kinetic {:.4g} J, strain {:.4g} J, "
              "{} rollback(s), {} sub-step(s) at the end",
              steps, ms, ms > 0 ? 1000.0 / ms : 0.0, run.energies.kinetic, run.energies.strain,
              run.rollbacks, run.final_substeps);
    const absl::Status written =
        dynsolid::tools::WriteOutputs(*d, timings, loaded->origin, run, control, out);
    if (!written.ok()) {
      std::cerr << "dynsolid-sim: " << written.message() << "\n";
      return 1;
    }
    std::ofstream(out + "/trace.csv") << trace;
    log->info("wrote {}/stats.json, trace.csv, boundary.obj, boundary.ply, volume.vtu", out);
    return 0;
  }
  const absl::Status written =
      dynsolid::tools::WriteOutputs(*d, timings, loaded->origin, run, control, out);
  log->info("wrote {}/stats.json, boundary.obj, boundary.ply, volume.vtu", out);
  return 0;
}
