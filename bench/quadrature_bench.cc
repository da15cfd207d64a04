// The local-frame model's two products for cubic elements that share no
// matrix: dense matrices per group against the quadrature points
// (models/cubic_quadrature.h). Per scene, with the scene's own material or
// a graded one (every sample painted a value of its own, as a brush's
// falloff leaves it): the model's build time, and its Forces time per call
// and per element on one thread: the local-frame model with float products
// (the stepping default) and the corotational model (Forces in double).
// Prints figures; asserts nothing.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "solver/common/worker_pool.h"
#include "solver/models/corotational.h"
#include "solver/models/local_frame.h"
#include "solver/models/measure.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

struct Case {
  std::string scene;
  int levels;
  bool graded;
  bool corotational = false;
};

// 0: every group dense; -1: the model's default.
std::vector<int32_t> g_sizes = {0, -1};

int Run(const Case& c) {
  auto scene = scene::BuiltinScene(c.scene);
  if (!scene.ok()) return 1;
  auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(), c.levels);
  if (!d.ok()) return 1;
  const Points rest = d->node_matrix * d->control().positions();
  const models::MaterialSampler uniform = [](const Eigen::Vector3d&, int32_t) {
    return models::MaterialPoint{1e5, 0.3, 1000, 0};
  };
  const models::MaterialSampler graded = [](const Eigen::Vector3d& x, int32_t) {
    return models::MaterialPoint{1e5 * (1.5 + std::sin(2.0 * x.x() + x.z())), 0.3, 1000, 0};
  };
  const models::ElementLayout layout = models::BuildElementLayout(
      d->elements, rest, d->hierarchy.control_cell, c.graded ? graded : uniform);
  const int32_t nodes = d->elements.num_nodes();
  WorkerPool pool(1);
  Points x = rest;
  for (int64_t i = 0; i < x.rows(); ++i) {
    x(i, 0) += 1e-3 * std::sin(1.0 + 2.0 * i);
    x(i, 2) += 1e-3 * std::cos(3.0 * i);
  }
  const int64_t cubic = layout.blocks[0].size();
  double dense_ms = 0, dense_lin_ms = 0;
  for (int32_t size_arg : g_sizes) {
    const int32_t group_size =
        size_arg >= 0 ? size_arg
                      : (c.corotational ? models::kEveryGroup : models::kQuadratureGroupSize);
    const auto t0 = Clock::now();
    std::unique_ptr<models::InternalForceModel> m;
    int64_t at_points = 0;
    if (c.corotational) {
      auto corot = std::make_unique<models::CorotationalModel>(layout, rest, pool, nullptr,
                                                               group_size);
      at_points = corot->quadrature_elements();
      m = std::move(corot);
    } else {
      auto lf = std::make_unique<models::LocalFrameModel>(
          layout, models::DeformationMeasure(d->fine(), d->elements, rest, 1), nodes, pool,
          nullptr, /*float_products=*/true, group_size);
      at_points = lf->quadrature_elements();
      m = std::move(lf);
    }
    const double build_ms = Ms(Clock::now() - t0);
    Points g;
    std::vector<double> elements_ms;
    for (int k = 0; k < 30; ++k) {
      m->Forces(x, g);
      elements_ms.push_back(m->last_timing().elements_ms);
    }
    std::sort(elements_ms.begin(), elements_ms.end());
    const double ms = elements_ms[elements_ms.size() / 2];
    // The corotational linearization in float (backward Euler's CG products).
    double lin_ms = 0;
    if (c.corotational) {
      auto* corot = static_cast<models::CorotationalModel*>(m.get());
      corot->SetSinglePrecisionLinearized(true);
      std::vector<double> t;
      Points kv;
      for (int k = 0; k < 30; ++k) {
        const auto a = Clock::now();
        corot->ApplyLinearized(x, kv);
        t.push_back(Ms(Clock::now() - a));
      }
      std::sort(t.begin(), t.end());
      lin_ms = t[t.size() / 2];
    }
    if (group_size == 0) dense_ms = ms;
    std::printf(
        "%-7s L%d %-5s %-7s %-10s %5lld cubic (%5lld at points) %5zu cubic groups: build %7.1f ms, "
        "element pass %6.3f ms (%.2f us per element)%s%s\n",
        c.scene.c_str(), c.levels, c.corotational ? "corot" : "local", c.graded ? "graded" : "uniform",
        group_size == 0 ? std::string("dense").c_str()
        : group_size == models::kEveryGroup ? std::string("quad all").c_str()
                                             : ("quad<=" + std::to_string(group_size)).c_str(), static_cast<long long>(cubic),
        static_cast<long long>(at_points), layout.blocks[0].groups.size(), build_ms,
        ms, 1e3 * ms / static_cast<double>(layout.blocks[0].size() + layout.blocks[1].size() +
                                           layout.blocks[2].size()),
        group_size == 0 ? ""
                        : (" | " + std::to_string(dense_ms / ms).substr(0, 4) + "x the dense pass")
                              .c_str(),
        c.corotational
            ? (", float linearization " + std::to_string(lin_ms).substr(0, 5) + " ms" +
               (group_size == 0 ? std::string()
                                : " (" + std::to_string(dense_lin_ms / lin_ms).substr(0, 4) +
                                      "x the dense)"))
                  .c_str()
            : "");
    if (group_size == 0) dense_lin_ms = lin_ms;
  }
  return 0;
}

}  // namespace
}  // namespace dynsolid

int main(int argc, char** argv) {
  // Optional: the group sizes to compare (0: every group dense).
  if (argc > 1) {
    dynsolid::g_sizes.clear();
    for (int i = 1; i < argc; ++i) dynsolid::g_sizes.push_back(std::atoi(argv[i]));
  }
  std::printf("one thread; local frame with float products, corotational in double (its Forces); "
              "element pass = the model's element phase (frames, "
              "products, sums), median of 30\n");
  for (const dynsolid::Case& c : std::vector<dynsolid::Case>{{"torus", 2, false},
                                                             {"nozzle", 2, false},
                                                             {"block3", 2, true},
                                                             {"block4", 2, true},
                                                             {"chair", 2, true},
                                                             {"nozzle", 2, false, true},
                                                             {"block4", 2, true, true},
                                                             {"block3", 2, false, true}}) {
    if (dynsolid::Run(c) != 0) return 1;
  }
  return 0;
}
