#include "solver/scene/build.h"

#include <chrono>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::scene {
namespace {

class Stopwatch {
 public:
  double LapMs() {
    const auto now = std::chrono::steady_clock::now();
    const double ms = std::chrono::duration<double, std::milli>(now - start_).count();
    start_ = now;
    return ms;
  }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

absl::StatusOr<int> Levels(const Scene& scene, std::optional<int> levels) {
  const int l = levels.value_or(scene.subdivision().levels());
  if (l < 0 || l > 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("subdivision levels must be in 0..4, got ", l));
  }
  return l;
}

absl::Status WithPrefix(const absl::Status& s, std::string_view prefix) {
  return absl::Status(s.code(), std::string(prefix) + std::string(s.message()));
}

}  // namespace

absl::StatusOr<Discretization> Discretize(const Scene& scene, const mesh::MeshInput& control,
                                          std::optional<int> levels, BuildTimings* timings) {
  RETURN_IF_ERROR(Levels(scene, levels).status());
  Stopwatch clock;
  ASSIGN_OR_RETURN(mesh::CellComplex base, mesh::CellComplex::FromInput(control));
  const double validate_ms = clock.LapMs();
  absl::StatusOr<Discretization> d = Discretize(scene, std::move(base), levels, timings);
  if (timings != nullptr) timings->validate_ms = validate_ms;
  return d;
}

absl::StatusOr<Discretization> Discretize(const Scene& scene, mesh::CellComplex base,
                                          std::optional<int> levels, BuildTimings* timings) {
  BuildTimings local_timings;
  BuildTimings& t = timings != nullptr ? *timings : local_timings;
  Stopwatch clock;
  ASSIGN_OR_RETURN(const int l, Levels(scene, levels));

  Discretization d;
  d.name = scene.name();
  d.input_cells = base.num_cells();

  // Sharp features on the input mesh: listed edges and creases.
  std::vector<std::array<int32_t, 2>> pairs;
  for (const EdgeRef& e : scene.sharp().edges()) pairs.push_back({e.v0(), e.v1()});
  absl::StatusOr<std::vector<uint8_t>> tags = subdivision::SharpEdgesFromPairs(base, pairs);
  if (!tags.ok()) return WithPrefix(tags.status(), "sharp.edges: ");
  subdivision::TagCreases(base, scene.sharp().crease_angle_degrees(), *tags);
  for (uint8_t x : *tags) d.sharp_control_edges += x;

  // Local subdivision of chosen control cells makes the control mesh.
  auto control_mesh = std::make_shared<mesh::CellComplex>(std::move(base));
  if (scene.mesh().refine_cells_size() > 0) {
    subdivision::SubdivisionOptions options;
    options.sharp_edges = *std::move(tags);
    for (int32_t c : scene.mesh().refine_cells()) {
      if (c < 0 || c >= control_mesh->num_cells()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "mesh.refine_cells: cell ", c, " is out of range [0, ", control_mesh->num_cells(),
            ")"));
      }
      options.cells.push_back(c);
    }
    options.validate_geometry = true;
    absl::StatusOr<subdivision::Level> level =
        subdivision::SubdivideOnce(*control_mesh, options);
    if (!level.ok()) return WithPrefix(level.status(), "mesh.refine_cells: ");
    d.locally_refined_cells = static_cast<int32_t>(options.cells.size());
    control_mesh = std::make_shared<mesh::CellComplex>(std::move(level->fine));
    tags = std::move(level->sharp_edges);
  }
  t.local_refine_ms = clock.LapMs();

  d.control_sharp = *tags;
  // The finest cells are classified while the last level's product runs.
  ASSIGN_OR_RETURN(d.hierarchy,
                   subdivision::Subdivide(std::move(control_mesh), l, *std::move(tags),
                                          [&](const mesh::CellComplex& fine) {
                                            d.elements = fem::ClassifyElements(fine);
                                          }));
  t.subdivide_ms = clock.LapMs();
  if (d.elements.num_virtual_nodes == 0) {
    d.node_matrix = std::move(d.hierarchy.a);
  } else {
    d.node_matrix = fem::NodeMatrix(*d.hierarchy.fine, d.hierarchy.a, d.elements);
  }
  d.hierarchy.a = subdivision::SparseMatrix();  // its rows lead node_matrix
  t.classify_ms = clock.LapMs();
  return d;
}

absl::StatusOr<Discretization> BuildDiscretization(const Scene& scene, std::string_view base_dir,
                                                   std::optional<int> levels,
                                                   BuildTimings* timings) {
  Stopwatch clock;
  ASSIGN_OR_RETURN(mesh::MeshInput input, ControlMeshInput(scene, base_dir));
  const double load_ms = clock.LapMs();
  absl::StatusOr<Discretization> d = Discretize(scene, input, levels, timings);
  if (timings != nullptr) timings->load_ms = load_ms;
  return d;
}

}  // namespace dynsolid::scene
