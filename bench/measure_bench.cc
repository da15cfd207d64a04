// The local-frame deformation measure alone (measure.h), one thread: its
// forward pass (delta from d) and its transpose, with quadrilaterals run
// four corners to a register (the models' path) and with every corner on
// its own (the per-corner path the tests hold it to), at a few block sizes.
// Prints nanoseconds per edge-or-corner term, best of several rounds, and
// the two paths' largest difference.
//
//   measure_bench [max_elements=50000]
//
// Prints figures only; nothing here is a test.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bench/best_ms.h"
#include "solver/models/measure.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"

int main(int argc, char** argv) {
  const int64_t max_elements = argc > 1 ? std::atoll(argv[1]) : 50000;
  std::printf("# Deformation measure, one thread: ns per term (edges + corners)\n\n");
  using dynsolid::models::QuadPath;
  const QuadPath paths[] = {QuadPath::kPerCorner, QuadPath::kAvx2, QuadPath::kAvx512};
  std::printf("fastest quadrilateral path here: %s\n\n",
              dynsolid::models::QuadPathName(dynsolid::models::FastestQuadPath()));
  std::printf("| block | nodes | edges | corners | quads | path | forward | transpose | "
              "forward vs per-corner | transpose vs per-corner | max rel. difference from "
              "per-corner |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |\n");
  for (int n : {3, 5, 7, 9}) {
    if (int64_t{n} * n * n * 64 > max_elements) break;
    auto scene = dynsolid::scene::BuiltinScene("block3");
    if (!scene.ok()) return 1;
    scene->mutable_mesh()->mutable_block()->set_nx(n);
    scene->mutable_mesh()->mutable_block()->set_ny(n);
    scene->mutable_mesh()->mutable_block()->set_nz(n);
    auto d = dynsolid::scene::BuildDiscretization(*scene, dynsolid::scene::BuiltinSceneDir(), 2);
    if (!d.ok()) {
      std::printf("| %d^3 | failed: %s |\n", n, std::string(d.status().message()).c_str());
      continue;
    }
    const dynsolid::Points rest = d->node_matrix * d->control().positions();
    // A smooth deformation (bend, twist and stretch) and a smooth y.
    dynsolid::Points x = rest, y = rest;
    for (int64_t i = 0; i < rest.rows(); ++i) {
      const double a = 0.05 * rest(i, 2), c = std::cos(a), s = std::sin(a);
      x(i, 0) = 1.02 * (c * rest(i, 0) - s * rest(i, 1));
      x(i, 1) = s * rest(i, 0) + c * rest(i, 1) + 0.01 * rest(i, 2) * rest(i, 2);
      for (int k = 0; k < 3; ++k) y(i, k) = std::cos(0.37 * i - 1.3 * k);
    }
    dynsolid::Points dc, tc;  // the per-corner path's results
    double fc = 0, bc = 0;
    for (QuadPath path : paths) {
      if (!dynsolid::models::QuadPathRuns(path)) {
        std::printf("| %d^3 | | | | | %s | does not run here | | | | |\n", n,
                    dynsolid::models::QuadPathName(path));
        continue;
      }
      const dynsolid::models::DeformationMeasure m(d->fine(), d->elements, rest, 1, path);
      dynsolid::Points dq, tq;
      m.Apply(x, dq);
      m.ApplyTranspose(x, y, tq);
      if (path == QuadPath::kPerCorner) dc = dq, tc = tq;
      const double diff =
          std::max((dq - dc).cwiseAbs().maxCoeff() / dc.cwiseAbs().maxCoeff(),
                   (tq - tc).cwiseAbs().maxCoeff() / tc.cwiseAbs().maxCoeff());
      const double terms = static_cast<double>(m.num_edges() + m.num_corners());
      const int reps = std::max(1, static_cast<int>(2e6 / terms));
      const double ns = 1e6 / terms;
      const double f = dynsolid::bench::BestMs(7, reps, [&] { m.Apply(x, dq); }) * ns;
      const double b = dynsolid::bench::BestMs(7, reps, [&] { m.ApplyTranspose(x, y, tq); }) * ns;
      if (path == QuadPath::kPerCorner) fc = f, bc = b;
      std::printf("| %d^3 | %lld | %lld | %lld | %lld | %s | %.2f | %.2f | %.2fx | %.2fx | "
                  "%.1e |\n",
                  n, static_cast<long long>(rest.rows()), static_cast<long long>(m.num_edges()),
                  static_cast<long long>(m.num_corners()), static_cast<long long>(m.num_quads()),
                  dynsolid::models::QuadPathName(path), f, b, fc / f, bc / b, diff);
    }
  }
  return 0;
}
