// Issue 42: dynsolid's answer for the Vega comparison. bench/scaling_bench
// prints times and memory but not where the block went, so this probe builds
// the same scene (the text below mirrors SceneText in bench/scaling_bench.cc;
// keep them in step) and prints the top face's mean x displacement after a
// fixed number of steps, one line per solver:
//
//   dynsolid n=12 solver=factored top_dx=... steps_total=45
//
// compare.sh compiles it outside the repository (under its build dir) with the
// flags of scaling_bench and links it against the already built libraries in
// build/release; it is not part of the repository's build.
//
//   dynsolid_top_dx --n=12 [--solvers=factored,cg,backward_euler] [--steps_total=45]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"

namespace {

std::string SceneText(int n, const std::string& solver) {
  const double size = 3.0, top = size, dx = size / n;
  std::string loads;
  const double share = 2e4 / ((n + 1) * (n + 1));
  auto inside = [&](double x) { return std::clamp(x, 1e-6, size - 1e-6); };
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= n; ++j) {
      loads += absl::StrCat("point_forces { position { x: ", inside(i * dx), " y: ",
                            inside(j * dx), " z: ", top * (1 - 1e-9), " } force { x: ", share,
                            " } } ");
    }
  }
  const std::string integrator =
      solver == "backward_euler" ? "BACKWARD_EULER" : "CENTRAL_DIFFERENCE";
  const std::string solve = solver == "cg" ? "CG" : "FACTORED";
  return absl::StrCat(
      "name: \"block", n, "\" mesh { block { nx: ", n, " ny: ", n, " nz: ", n,
      " size { x: ", size, " y: ", size, " z: ", size, " } } } subdivision { levels: 0 } ",
      "materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 2000 } } ",
      "constraints { fixed { box { min { x: -1 y: -1 z: -1e-6 } max { x: 4 y: 4 z: 1e-6 } } } } ",
      "loads { ", loads, "} ",
      "solver { model: COROTATIONAL corotation: CONTROL_CELL integrator: ", integrator,
      " time_step: 1e-3 mass: CONSISTENT explicit_solve: ", solve, " }");
}

}  // namespace

int main(int argc, char** argv) {
  int n = 8, steps_total = 45;
  std::string solvers = "factored,cg,backward_euler";
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg.rfind("--n=", 0) == 0) n = std::atoi(arg.c_str() + 4);
    else if (arg.rfind("--steps_total=", 0) == 0) steps_total = std::atoi(arg.c_str() + 14);
    else if (arg.rfind("--solvers=", 0) == 0) solvers = arg.substr(10);
    else {
      std::fprintf(stderr, "usage: %s --n=N [--solvers=...] [--steps_total=45]\n", argv[0]);
      return 2;
    }
  }
  int failures = 0;
  for (absl::string_view sv : absl::StrSplit(solvers, ',')) {
    const std::string solver(sv);
    auto scene = dynsolid::scene::ParseScene(SceneText(n, solver), "vega_compare");
    if (!scene.ok()) {
      std::printf("dynsolid n=%d solver=%s failed=parse\n", n, solver.c_str());
      ++failures;
      continue;
    }
    auto d = dynsolid::scene::BuildDiscretization(*scene, "", std::nullopt);
    auto s = d.ok() ? dynsolid::solid::Solid::Create(*scene, *std::move(d))
                    : absl::StatusOr<std::unique_ptr<dynsolid::solid::Solid>>(d.status());
    if (!s.ok()) {
      std::printf("dynsolid n=%d solver=%s failed=build\n", n, solver.c_str());
      ++failures;
      continue;
    }
    dynsolid::solid::Solid& solid = **s;
    const auto rest = solid.control_positions();  // a copy: the rest positions
    bool ok = true;
    for (int i = 0; i < steps_total && ok; ++i) ok = solid.Step().ok();
    if (!ok) {
      std::printf("dynsolid n=%d solver=%s failed=step\n", n, solver.c_str());
      ++failures;
      continue;
    }
    const auto& p = solid.control_positions();
    double sum = 0;
    int count = 0;
    for (int i = 0; i < rest.rows(); ++i) {
      if (std::abs(rest(i, 2) - 3.0) < 1e-9) {
        sum += p(i, 0) - rest(i, 0);
        ++count;
      }
    }
    std::printf("dynsolid n=%d solver=%s top_nodes=%d top_dx=%.6e steps_total=%d\n", n,
                solver.c_str(), count, count ? sum / count : 0.0, steps_total);
    std::fflush(stdout);
  }
  return failures == 0 ? 0 : 1;
}
