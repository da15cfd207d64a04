// Paint latency: how long Solid::PaintMaterial holds the simulation (a
// sphere of stiffer material painted five times over the default scene, or
// the scene named on the command line). Prints figures only.
//   paint_bench [scene=block3]
#include <chrono>
#include <cstdio>
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
int main(int argc, char** argv) {
  auto scene = dynsolid::scene::BuiltinScene(argc > 1 ? argv[1] : "block3");
  auto d = dynsolid::scene::BuildDiscretization(*scene, dynsolid::scene::BuiltinSceneDir(), std::nullopt);
  auto s = dynsolid::solid::Solid::Create(*scene, *std::move(d));
  if (!s.ok()) { std::printf("%s\n", std::string(s.status().message()).c_str()); return 1; }
  dynsolid::MaterialPaint paint;
  auto* sp = paint.mutable_region()->mutable_sphere();
  sp->mutable_center()->set_x(1.5); sp->mutable_center()->set_y(1.5); sp->mutable_center()->set_z(2.5);
  sp->set_radius(0.8);
  paint.mutable_material()->set_young_modulus(3e5);
  paint.set_strength(1.0);
  for (int i = 0; i < 5; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    auto st = (*s)->PaintMaterial(paint);
    auto t1 = std::chrono::steady_clock::now();
    std::printf("paint %d: %s %.1f ms\n", i, st.ok() ? "ok" : std::string(st.message()).c_str(),
                std::chrono::duration<double, std::milli>(t1 - t0).count());
    paint.mutable_material()->set_young_modulus(3e5 + 1e4 * (i + 1));
  }
}
