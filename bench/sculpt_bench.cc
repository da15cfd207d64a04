// Sculpting hold times: how long a topology edit (the pure edit, the edited
// scene, the new solid with its state carried over) and a restore (what undo
// does within one topology) hold a session's loop. Prints figures only.
//   sculpt_bench [scene=block3] [levels=-1: the scene's] [edit: all, or
//                extrude, delete, subdivide, sharp or merge alone]
//                [repetitions=3]
// Each edit is applied to the scene's solid after 20 steps, timed over the
// repetitions (median and best printed, and the best against the
// 50 ms target for an edit of the chair at two levels), with where the
// last one's time went. The first line names the CPU: figures differ
// between machines (and a shared VM's vary from run to run: compare bests).
#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "absl/strings/str_format.h"
#include "google/protobuf/text_format.h"
#include "bench/cpu_name.h"
#include "bench/figures.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/sculpt/apply.h"
#include "solver/solid/solid.h"

namespace {

using dynsolid::bench::Median;

double Ms(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace dynsolid;
  const std::string name = argc > 1 ? argv[1] : "block3";
  const int levels = argc > 2 ? std::atoi(argv[2]) : -1;
  absl::StatusOr<Scene> scene = scene::BuiltinScene(name);
  if (!scene.ok()) {
    std::printf("%s\n", std::string(scene.status().message()).c_str());
    return 1;
  }
  auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(),
                                      levels >= 0 ? std::optional<int>(levels) : std::nullopt);
  if (!d.ok()) {
    std::printf("%s\n", std::string(d.status().message()).c_str());
    return 1;
  }
  if (levels >= 0) scene->mutable_subdivision()->set_levels(levels);
  auto s = solid::Solid::Create(*scene, *std::move(d));
  if (!s.ok()) {
    std::printf("%s\n", std::string(s.status().message()).c_str());
    return 1;
  }
  solid::Solid& solid = **s;
  for (int i = 0; i < 20; ++i) (void)solid.Step();
  const mesh::CellComplex& c = solid.discretization().control();
  // Targets picked on this mesh: the boundary face with the highest
  // centroid, the cell with the highest centroid, and the cell nearest the
  // middle.
  int32_t top_face = -1, top_cell = 0, mid_cell = 0;
  Eigen::Vector3d lo = c.positions().colwise().minCoeff(), hi = c.positions().colwise().maxCoeff();
  const Eigen::Vector3d mid = 0.5 * (lo + hi);
  for (int32_t f = 0; f < c.num_faces(); ++f) {
    if (c.face_is_boundary(f) &&
        (top_face < 0 || c.FaceCentroid(f).z() > c.FaceCentroid(top_face).z())) {
      top_face = f;
    }
  }
  for (int32_t k = 0; k < c.num_cells(); ++k) {
    if (c.CellCentroid(k).z() > c.CellCentroid(top_cell).z()) top_cell = k;
    if ((c.CellCentroid(k) - mid).norm() < (c.CellCentroid(mid_cell) - mid).norm()) mid_cell = k;
  }
  const double size = (hi - lo).maxCoeff();
  // A merge bridges two boundary faces that face each other across a gap:
  // the nearest such pair of one vertex count sharing no vertex, each in
  // front of the other and about opposite it (boundary loops run outward).
  auto normal = [&](int32_t f) {
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    const auto loop = c.face_vertices(f);
    for (size_t i = 0; i < loop.size(); ++i) {
      n += c.positions().row(loop[i]).transpose().cross(
          c.positions().row(loop[(i + 1) % loop.size()]).transpose());
    }
    return Eigen::Vector3d(n.normalized());
  };
  int32_t merge_a = -1, merge_b = -1;
  double nearest = INFINITY;
  for (int32_t a = 0; a < c.num_faces(); ++a) {
    if (!c.face_is_boundary(a)) continue;
    const Eigen::Vector3d na = normal(a), ca = c.FaceCentroid(a);
    const auto la = c.face_vertices(a);
    for (int32_t b = a + 1; b < c.num_faces(); ++b) {
      const auto lb = c.face_vertices(b);
      if (!c.face_is_boundary(b) || lb.size() != la.size()) continue;
      if (std::any_of(la.begin(), la.end(),
                      [&](int32_t v) { return std::find(lb.begin(), lb.end(), v) != lb.end(); })) {
        continue;
      }
      const Eigen::Vector3d nb = normal(b), d = c.FaceCentroid(b) - ca;
      const double gap = d.dot(na);
      if (na.dot(nb) > -0.95 || gap <= 0 || -d.dot(nb) <= 0) continue;
      if ((d - gap * na).norm() > 0.25 * gap) continue;  // across, not aside
      if (d.norm() < nearest) {
        nearest = d.norm();
        merge_a = a;
        merge_b = b;
      }
    }
  }
  // The top face's first edge, tagged sharp, or untagged if it is (the
  // chair's crease angle tags its box edges already: tagging one again
  // changes nothing).
  const auto top_loop = c.face_vertices(top_face);
  const int32_t top_edge = c.FindEdge(top_loop[0], top_loop[1]);
  const std::vector<uint8_t>& tags = solid.discretization().control_sharp;
  const bool untag = top_edge >= 0 && top_edge < static_cast<int32_t>(tags.size()) && tags[top_edge] != 0;
  const std::vector<std::pair<std::string, std::string>> edits = {
      {"extrude", "extrude_faces { faces: " + std::to_string(top_face) +
                      " distance: " + std::to_string(0.2 * size / 3) + " }"},
      {"delete", "delete_cells { cells: " + std::to_string(top_cell) + " }"},
      {"subdivide", "subdivide_cells { cells: " + std::to_string(mid_cell) + " }"},
      {"sharp", std::string("sharp_edges { sharp: ") + (untag ? "false" : "true") +
                    " edges { v0: " + std::to_string(top_loop[0]) +
                    " v1: " + std::to_string(top_loop[1]) + " } }"},
      {"merge", "merge_faces { face_a: " + std::to_string(merge_a) +
                    " face_b: " + std::to_string(merge_b) + " }"},
  };
  std::printf("sculpt_bench: %s at %d levels: %d control cells, %lld elements, %d threads, %s\n",
              name.c_str(), solid.discretization().hierarchy.levels, c.num_cells(),
              static_cast<long long>(solid.discretization().elements.cubic_cell.size() + solid.discretization().elements.linear_cell.size() + solid.discretization().elements.pyramid_cell.size()), solid.threads(), dynsolid::bench::CpuName().c_str());
  constexpr double kTargetMs = 50;  // an edit of the chair at two levels, rebuild included
  std::printf("| what | median ms | best ms | best / %.0f ms | result |\n| --- | ---: | ---: | ---: | --- |\n",
              kTargetMs);
  std::vector<std::string> phases;
  const std::string only = argc > 3 ? argv[3] : "";
  const int repetitions = argc > 4 ? std::max(1, std::atoi(argv[4])) : 3;
  for (const auto& [what, text] : edits) {
    if (!only.empty() && only != "all" && only != what) continue;
    TopologyEdit e;
    google::protobuf::TextFormat::ParseFromString(text, &e);
    std::vector<double> ms;
    std::string result;
    for (int r = 0; r < repetitions; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      absl::StatusOr<sculpt::AppliedEdit> a = sculpt::ApplyEdit(*scene, solid, e);
      ms.push_back(Ms(t0));
      result = a.ok() ? a->summary + absl::StrFormat(" (%d cubic, %d linear groups; %d material arrays; %d estimate passes)", a->solid->build_report().cubic_groups, a->solid->build_report().linear_groups, a->solid->build_report().material_arrays, a->solid->build_report().stable_step_passes) : std::string(a.status().message());
      if (a.ok() && r == repetitions - 1) {
        const auto& p = a->prepare_phases;
        const auto& b = a->solid->build_report();
        phases.push_back(absl::StrFormat(
            "| %s | %d of %d | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f |",
            what, b.mass_cells_made, b.control_cell_partials, p.edit, p.discretize, p.build - b.build_ms, b.phases.layout, b.phases.model,
            b.phases.mass, b.phases.surface, b.phases.stable_step, b.phases.k0,
            b.build_ms - b.phases.layout - b.phases.model - b.phases.mass -
                b.phases.stable_step - b.phases.k0,
            a->milliseconds - a->prepare_milliseconds));
      }
    }
    const double best = *std::min_element(ms.begin(), ms.end());
    std::printf("| %s | %.1f | %.1f | %.2f | %s |\n", what.c_str(), Median(ms), best, best / kTargetMs,
                result.c_str());
  }
  std::printf("\nwhere an edit's time goes (ms, the last run):\n"
              "| edit | cells made | edit | discretize | transfer, integrator | layout | model | mass | surface (in model) | "
              "stable step | K0 | rest of build | finish |\n"
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const std::string& row : phases) std::printf("%s\n", row.c_str());
  // Undo within one topology: restore a saved state.
  const std::string state = solid.SaveState();
  std::vector<double> save_ms, restore_ms;
  for (int r = 0; r < 3; ++r) {
    auto t0 = std::chrono::steady_clock::now();
    const std::string bytes = solid.SaveState();
    save_ms.push_back(Ms(t0));
    t0 = std::chrono::steady_clock::now();
    (void)solid.RestoreStateAtClock(state, solid.time(), solid.steps());
    restore_ms.push_back(Ms(t0));
  }
  std::printf("| save state (every undoable command) | %.2f | %zu bytes |\n", Median(save_ms),
              state.size());
  std::printf("| restore state (undo, redo) | %.2f | |\n", Median(restore_ms));
  return 0;
}
