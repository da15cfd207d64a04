// Paint latency: how long Solid::PaintMaterial takes (a sphere of stiffer
// material painted five times over the default scene, or the scene named on
// the command line), and its two halves: PreparePaint, which the server runs
// off the simulation loop, and ApplyPaint, which holds the loop. Prints
// figures only. Then the painted solid's SaveState (what the undo history
// copies for every undoable command).
//   paint_bench [scene=block3] [model=the scene's: local_frame, corotational,
//                corotational_cells, or "-"] [radius=0.8]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
int main(int argc, char** argv) {
  auto scene = dynsolid::scene::BuiltinScene(argc > 1 ? argv[1] : "block3");
  if (!scene.ok()) { std::printf("%s\n", std::string(scene.status().message()).c_str()); return 1; }
  if (argc > 2 && std::string(argv[2]) != "-") {
    // The brush speed figures (docs/sculpt.md, "Brush speed") are for
    // block3 with the local frame.
    const std::string model = argv[2];
    dynsolid::SolverSettings* s = scene->mutable_solver();
    s->set_model(model == "local_frame" ? dynsolid::SolverSettings::LOCAL_FRAME
                                        : dynsolid::SolverSettings::COROTATIONAL);
    s->set_corotation(model == "corotational_cells" ? dynsolid::SolverSettings::CONTROL_CELL
                                                    : dynsolid::SolverSettings::COROTATION_DEFAULT);
    if (model == "local_frame" && s->integrator() == dynsolid::SolverSettings::BACKWARD_EULER) {
      s->set_integrator(dynsolid::SolverSettings::CENTRAL_DIFFERENCE);
    }
  }
  std::printf("paint_bench: %s, %s\n", scene->name().c_str(),
              dynsolid::scene::ModelName(scene->solver()).c_str());
  auto d = dynsolid::scene::BuildDiscretization(*scene, dynsolid::scene::BuiltinSceneDir(), std::nullopt);
  auto s = dynsolid::solid::Solid::Create(*scene, *std::move(d));
  if (!s.ok()) { std::printf("%s\n", std::string(s.status().message()).c_str()); return 1; }
  dynsolid::MaterialPaint paint;
  auto* sp = paint.mutable_region()->mutable_sphere();
  sp->mutable_center()->set_x(1.5); sp->mutable_center()->set_y(1.5); sp->mutable_center()->set_z(2.5);
  sp->set_radius(argc > 3 ? std::atof(argv[3]) : 0.8);
  paint.mutable_material()->set_young_modulus(3e5);
  paint.set_strength(1.0);
  auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  for (int i = 0; i < 5; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    auto st = (*s)->PaintMaterial(paint);
    auto t1 = std::chrono::steady_clock::now();
    std::printf("paint %d: %s %.1f ms", i, st.ok() ? "ok" : std::string(st.message()).c_str(),
                ms(t0, t1));
    paint.mutable_material()->set_young_modulus(3e5 + 1e4 * (i + 1));
    // The same kind of paint in halves.
    t0 = std::chrono::steady_clock::now();
    auto prepared = (*s)->PreparePaint(paint);
    t1 = std::chrono::steady_clock::now();
    auto applied = prepared.ok() ? (*s)->ApplyPaint(**prepared) : prepared.status();
    auto t2 = std::chrono::steady_clock::now();
    std::printf("; then prepare %.1f ms (off the loop) + apply %.2f ms (holds the loop)%s\n",
                ms(t0, t1), ms(t1, t2), applied.ok() ? "" : " FAILED");
    if (prepared.ok()) {
      const auto ph = dynsolid::solid::Solid::PhasesOf(**prepared);
      std::printf("  prepare: %lld samples painted; layout %.1f, model %.1f (%d cells made), "
                  "mass %.1f, stable step %.1f ms\n",
                  static_cast<long long>(ph.samples_painted), ph.layout, ph.model, ph.cells_made,
                  ph.mass, ph.stable);
    }
    paint.mutable_material()->set_young_modulus(3.05e5 + 1e4 * (i + 1));
  }
  // What every undoable command copies into the undo history once the solid
  // is painted: its state.
  double save_ms = 0;
  size_t bytes = 0;
  for (int i = 0; i < 5; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    bytes = (*s)->SaveState().size();
    save_ms = ms(t0, std::chrono::steady_clock::now());
  }
  std::printf("save state of the painted solid: %.2f ms (%zu bytes)\n", save_ms, bytes);
}
