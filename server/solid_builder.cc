#include "server/solid_builder.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <optional>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/common/build_watch.h"
#include "solver/common/status_macros.h"
#include "solver/scene/scene_loader.h"
#include "solver/sculpt/apply.h"

namespace dynsolid::server {
namespace {

constexpr int kMaxLevels = 4;

// "origin: message", unless the message already starts with the origin
// (the scene parser's "origin:line:col: ..." messages do).
absl::Status WithOrigin(const absl::Status& status, absl::string_view origin) {
  if (status.ok() || absl::StartsWith(status.message(), origin)) return status;
  return absl::Status(status.code(), absl::StrCat(origin, ": ", status.message()));
}

// Clients never make the server read its files: a scene they send must
// generate its mesh.
absl::Status RejectMeshFile(const Scene& scene, absl::string_view origin) {
  if (scene.mesh().source_case() != ControlMesh::kFile) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      origin, ": mesh.file (\"", scene.mesh().file(),
      "\") is not accepted in a scene sent to the server, which never reads its own files "
      "for a client; describe the mesh with a generator (mesh.block, mesh.beam, mesh.tube, "
      "mesh.torus, mesh.voxels) or use a builtin_scene"));
}

// Each vertex's valence within one level-0 cell (faces as vertex loops):
// the number of the cell's edges that meet there.
std::vector<int64_t> CellVertexValences(const std::vector<std::vector<int32_t>>& faces) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  for (const auto& loop : faces) {
    for (size_t i = 0; i < loop.size(); ++i) {
      const int32_t a = loop[i], b = loop[(i + 1) % loop.size()];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<int32_t> ends;
  for (const auto& [a, b] : edges) {
    ends.push_back(a);
    ends.push_back(b);
  }
  std::sort(ends.begin(), ends.end());
  std::vector<int64_t> valences;
  for (size_t i = 0; i < ends.size();) {
    size_t j = i;
    while (j < ends.size() && ends[j] == ends[i]) ++j;
    valences.push_back(static_cast<int64_t>(j - i));
    i = j;
  }
  return valences;
}

// Level-`levels` descendants (levels >= 1) of the level-1 child that
// MacCracken-Joy makes at a cell vertex of valence k. That child has 2k + 2
// vertices: two of valence k (the old vertex and the cell point) and 2k of
// valence 3, so it splits into 2 children of its own kind and 2k
// hexahedra, and a hexahedron into 8 hexahedra.
int64_t DescendantsOfVertexChild(int64_t k, int levels) {
  int64_t own_kind = 1, hexahedra = 0;
  for (int l = 1; l < levels; ++l) {
    hexahedra = 8 * hexahedra + 2 * k * own_kind;
    own_kind *= 2;
  }
  return own_kind + hexahedra;
}

}  // namespace

absl::StatusOr<SceneRequest> ResolveSceneRequest(const CreateSessionRequest& request) {
  SceneRequest out;
  switch (request.scene_source_case()) {
    case CreateSessionRequest::kBuiltinScene: {
      out.origin = absl::StrCat("builtin:", request.builtin_scene());
      ASSIGN_OR_RETURN(out.scene, scene::BuiltinScene(request.builtin_scene()));
      out.base_dir = scene::BuiltinSceneDir();
      break;
    }
    case CreateSessionRequest::kSceneText: {
      out.origin = "scene_text";
      ASSIGN_OR_RETURN(out.scene, scene::ParseScene(request.scene_text(), out.origin));
      RETURN_IF_ERROR(RejectMeshFile(out.scene, out.origin));
      break;
    }
    case CreateSessionRequest::kScene: {
      out.origin = "scene";
      out.scene = request.scene();
      RETURN_IF_ERROR(WithOrigin(scene::ValidateScene(out.scene), out.origin));
      RETURN_IF_ERROR(RejectMeshFile(out.scene, out.origin));
      break;
    }
    case CreateSessionRequest::SCENE_SOURCE_NOT_SET:
      return absl::InvalidArgumentError(
          "CreateSessionRequest.scene_source: set one of builtin_scene, scene_text or scene");
  }
  if (request.has_levels_override() && request.levels_override() != -1) {
    const int levels = request.levels_override();
    if (levels < 0 || levels > kMaxLevels) {
      return absl::InvalidArgumentError(absl::StrCat(
          "CreateSessionRequest.levels_override must be in 0..", kMaxLevels,
          " (or -1 to keep the scene's subdivision.levels), got ", levels));
    }
    out.levels = levels;
  }
  switch (request.model_override()) {
    case SolverSettings::MODEL_DEFAULT:
      break;
    case SolverSettings::LOCAL_FRAME:
      // Its frames are its own: no corotation setting goes with it.
      out.scene.mutable_solver()->set_model(request.model_override());
      out.scene.mutable_solver()->clear_corotation();
      break;
    case SolverSettings::COROTATIONAL:
      out.scene.mutable_solver()->set_model(request.model_override());
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "CreateSessionRequest.model_override must be LOCAL_FRAME (1) or COROTATIONAL (2), "
          "or MODEL_DEFAULT (0) to keep the scene's, got ",
          static_cast<int>(request.model_override())));
  }
  return out;
}

int64_t EstimateFineCells(const mesh::MeshInput& control, const Scene& scene, int levels) {
  const int64_t num_cells = static_cast<int64_t>(control.cells.size());
  std::vector<uint8_t> refined(num_cells, 0);
  for (int32_t c : scene.mesh().refine_cells()) {
    if (c >= 0 && c < num_cells) refined[c] = 1;
  }
  int64_t cells = 0;
  for (int64_t c = 0; c < num_cells; ++c) {
    // A locally refined cell is one level ahead of the others.
    const int l = levels + refined[c];
    if (l == 0) {
      ++cells;
      continue;
    }
    for (int64_t k : CellVertexValences(control.cells[c])) cells += DescendantsOfVertexChild(k, l);
  }
  return cells;
}

namespace {

// Memory model, calibrated with dynsolid-sim (peak RSS, /usr/bin/time -v,
// build plus two steps; bench/reports/reliability.md has the table).
// See EstimateSessionBytes.
//
// Measured peak-RSS growth of dynsolid-server for one CreateSession
// (VmHWM before and after), 2026-11-28:
//   block 10^3, level 0, local_frame (1000 cells, 512 cubic):    +32.7 MB
//   block 20^3, level 0, local_frame (8000 cells, 5832 cubic):  +730.1 MB
//   block 30^3, level 0, local_frame (27000 cells, 19683 cubic): past
//       +2715 MB and still building when stopped after 600 s
//   block3, level 2, corotational per control cell (1728 cells): +18.3 MB
//   block3, level 3, corotational per control cell (13824 cells): +92.0 MB
//   chair, level 2, corotational (4864 cells): +26.0 MB
//   beam, level 2, local_frame (640 cells, 152 cubic): +8.4 MB
//   beam, level 3, local_frame (5120 cells, 2808 cubic): +26.8 MB
//   mixed, level 2, local_frame (186 cells): +8.5 MB
// The local-frame model on an unsubdivided (level 0) mesh costs about 125 kB
// per cubic B-spline element (730 MB / 5832), which dominates; subdivided,
// it costs 5-13 kB per cell, as the corotational models do (5-11 kB).
// So: a fixed part and a per-cell cost by model and level, each rounded up
// from the largest figure measured; the
// implicit integrator (backward Euler, or AUTO which may choose it) has a
// global matrix on top, counted as doubling the per-cell cost (not
// measured: an upper guess).
constexpr double kFixedBytes = 16.0 * (1 << 20);
constexpr double kLocalFrameLevel0BytesPerCell = 128e3;
constexpr double kLocalFrameBytesPerCell = 16e3;
constexpr double kCorotationalBytesPerCell = 8e3;
constexpr double kImplicitFactor = 2;

std::string Mib(double bytes) { return absl::StrFormat("%.0f MiB", bytes / (1 << 20)); }

// The size checks of BuildSolid, before the control mesh is made (from the
// generator's parameters) and after (from the mesh): max_cells and
// max_session_bytes.
absl::Status CheckSize(const SceneRequest& request, double fine_cells, int levels,
                       const std::string& control, const BuildLimits& limits) {
  if (fine_cells > static_cast<double>(limits.max_cells)) {
    return absl::ResourceExhaustedError(absl::StrCat(
        request.origin, ": the solid would have about ", absl::StrFormat("%.0f", fine_cells),
        " cells (", control, ", ", levels,
        " subdivision levels), more than this server's limit of ", limits.max_cells,
        "; use fewer levels or a coarser control mesh"));
  }
  if (limits.max_session_bytes > 0) {
    const int64_t bytes =
        EstimateSessionBytes(request.scene, static_cast<int64_t>(std::min(fine_cells, 9e18)), levels);
    if (bytes > limits.max_session_bytes) {
      return absl::ResourceExhaustedError(absl::StrCat(
          request.origin, ": the solid would need about ", Mib(static_cast<double>(bytes)),
          " of memory (estimated from its ", absl::StrFormat("%.0f", fine_cells), " cells: ",
          control, ", ", levels, " subdivision levels, the ",
          scene::ModelName(request.scene.solver()), " model), more than this server's limit of ",
          Mib(static_cast<double>(limits.max_session_bytes)),
          " per session (--max_session_bytes); use fewer levels or a coarser control mesh"));
    }
  }
  return absl::OkStatus();
}

// This process's resident memory, bytes (0 when /proc does not say).
int64_t ResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  int64_t size = 0, resident = 0;
  if (!(statm >> size >> resident)) return 0;
  return resident * static_cast<int64_t>(sysconf(_SC_PAGESIZE));
}

// The check a build of `request` runs between its phases: the process's
// resident memory may grow by at most `factor` times `estimate` bytes from
// where it was when the build began. (Other sessions' memory moves the
// figure too; the factor leaves room for that.)
common::BuildCheck MemoryWatch(const SceneRequest& request, int64_t estimate, double factor) {
  const int64_t start = ResidentBytes();
  const double allowed = factor * static_cast<double>(estimate);
  return [start, allowed, estimate, factor, origin = request.origin](std::string_view phase) {
    const int64_t grown = ResidentBytes() - start;
    if (static_cast<double>(grown) <= allowed) return absl::OkStatus();
    return absl::ResourceExhaustedError(absl::StrCat(
        origin, ": the build was stopped after its ", std::string(phase), " phase: it had grown the server's "
        "memory by ", Mib(static_cast<double>(grown)), ", more than ", factor,
        " times the session's estimate of ", Mib(static_cast<double>(estimate)),
        " (--build_memory_factor); nothing of it was kept. The estimate is too low for "
        "this scene: use fewer levels or a coarser control mesh"));
  };
}

}  // namespace

int64_t EstimateSessionBytes(const Scene& scene, int64_t fine_cells, int levels) {
  const SolverSettings solver = scene::ResolvedSolverSettings(scene);
  double per_cell = kCorotationalBytesPerCell;
  if (solver.model() == SolverSettings::LOCAL_FRAME) {
    per_cell = levels == 0 ? kLocalFrameLevel0BytesPerCell : kLocalFrameBytesPerCell;
  }
  if (solver.integrator() == SolverSettings::BACKWARD_EULER ||
      solver.integrator() == SolverSettings::AUTO) {
    per_cell *= kImplicitFactor;
  }
  const double bytes = kFixedBytes + per_cell * static_cast<double>(fine_cells);
  return bytes >= 9e18 ? int64_t{9'000'000'000'000'000'000} : static_cast<int64_t>(bytes);
}

std::optional<double> GeneratedFineCells(const Scene& scene, int levels) {
  const ControlMesh& m = scene.mesh();
  double cells = 0;
  switch (m.source_case()) {
    case ControlMesh::kBlock:
      cells = double{1} * m.block().nx() * m.block().ny() * m.block().nz();
      break;
    case ControlMesh::kBeam:
      cells = double{1} * m.beam().cells_along() * m.beam().cells_across() *
              m.beam().cells_across();
      break;
    case ControlMesh::kTube:
      cells = double{1} * m.tube().segments() * m.tube().layers() * m.tube().slices();
      break;
    case ControlMesh::kTorus:
      cells = double{1} * m.torus().segments() * m.torus().cross() * m.torus().cross();
      break;
    case ControlMesh::kVoxels:
      for (const VoxelBox& b : m.voxels().boxes()) {
        if (b.subtract()) continue;
        cells += double{1} * std::max(0, b.x1() - b.x0()) * std::max(0, b.y1() - b.y0()) *
                 std::max(0, b.z1() - b.z0());
      }
      break;
    default:
      return std::nullopt;
  }
  // Every generated cell is a hexahedron: 8 children per level, and a
  // locally refined one is a level ahead (7 * 8^L more cells each, an
  // upper bound as refine_cells may repeat a cell).
  const double per_cell = std::pow(8.0, levels);
  return cells * per_cell + 7.0 * per_cell * scene.mesh().refine_cells_size();
}

int SimThreads(int sim_threads) {
  if (sim_threads > 0) return sim_threads;
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  return std::clamp(cores - 1, 1, 8);
}

absl::StatusOr<BuiltSolid> BuildSolid(const SceneRequest& request, const BuildLimits& limits) {
  const auto start = std::chrono::steady_clock::now();
  const int levels = request.levels.value_or(request.scene.subdivision().levels());
  // A generated mesh is sized from its parameters first: a request for
  // millions of cells is refused before any of them is made (making the
  // control mesh alone of a 100^3 block takes hundreds of MB).
  if (std::optional<double> cells = GeneratedFineCells(request.scene, levels)) {
    const double control_cells = *cells / std::pow(8.0, levels);
    if (absl::Status s = CheckSize(request, *cells, levels,
                                   absl::StrFormat("%.0f generated control cells", control_cells),
                                   limits);
        !s.ok()) {
      return s;
    }
  }
  absl::StatusOr<mesh::MeshInput> control =
      scene::ControlMeshInput(request.scene, request.base_dir);
  if (!control.ok()) return WithOrigin(control.status(), request.origin);

  const int64_t estimate = EstimateFineCells(*control, request.scene, levels);
  if (absl::Status s = CheckSize(request, static_cast<double>(estimate), levels,
                                 absl::StrCat(control->cells.size(), " control cells"), limits);
      !s.ok()) {
    return s;
  }

  // The build is watched against its estimate from here on.
  std::optional<common::ScopedBuildWatch> watch;
  if (limits.build_memory_factor > 0) {
    watch.emplace(MemoryWatch(request, EstimateSessionBytes(request.scene, estimate, levels),
                              limits.build_memory_factor));
  }
  absl::StatusOr<scene::Discretization> d =
      scene::Discretize(request.scene, *control, request.levels);
  if (!d.ok()) return WithOrigin(d.status(), request.origin);
  RETURN_IF_ERROR(common::CheckBuildWatch("subdivision"));
  SolidStats stats = ComputeStats(*d, 0);
  absl::StatusOr<std::unique_ptr<solid::Solid>> solid =
      solid::Solid::Create(request.scene, *std::move(d), SimThreads(limits.sim_threads));
  if (!solid.ok()) return WithOrigin(solid.status(), request.origin);
  const double ms = std::chrono::duration<double, std::milli>(
                        std::chrono::steady_clock::now() - start).count();
  stats.set_build_milliseconds(ms);
  const solid::BuildReport& report = (*solid)->build_report();
  stats.set_model(scene::ModelName(request.scene.solver()));
  stats.set_integrator(report.implicit ? "backward_euler" : "central_difference");
  stats.set_substeps(report.substeps);
  BuiltSolid out;
  out.stats = std::move(stats);
  out.solid = std::shared_ptr<solid::Solid>(*std::move(solid));
  out.discretization =
      std::shared_ptr<const scene::Discretization>(out.solid, &out.solid->discretization());
  return out;
}

SolidStats ComputeStats(const scene::Discretization& d, double build_milliseconds) {
  const auto& e = d.elements;
  const int32_t cells = d.fine().num_cells();
  const mesh::CellComplex::BoundaryCounts boundary = d.fine().CountBoundary();
  const auto share = [cells](int32_t n) {
    return cells > 0 ? static_cast<double>(n) / cells : 0.0;
  };
  SolidStats s;
  s.set_control_cells(d.control().num_cells());
  s.set_control_vertices(d.control().num_vertices());
  s.set_levels(d.hierarchy.levels);
  s.set_cells(cells);
  s.set_vertices(d.fine().num_vertices());
  s.set_nodes(e.num_nodes());
  s.set_cubic_elements(e.num_cubic());
  s.set_linear_elements(e.num_linear());
  s.set_pyramid_elements(e.num_pyramid());
  s.set_pyramid_cells(e.num_pyramid_cells());
  s.set_cubic_fraction(share(e.num_cubic()));
  s.set_linear_fraction(share(e.num_linear()));
  s.set_pyramid_fraction(share(e.num_pyramid_cells()));
  s.set_boundary_vertices(static_cast<int32_t>(boundary.vertices));
  s.set_boundary_edges(static_cast<int32_t>(boundary.edges));
  s.set_boundary_faces(static_cast<int32_t>(boundary.faces));
  s.set_boundary_euler(static_cast<int32_t>(boundary.euler()));
  s.set_build_milliseconds(build_milliseconds);
  return s;
}

SolidFactory MakeSolidFactory(SceneRequest request, BuildLimits limits) {
  return [request = std::move(request),
          limits](const Scene* edited) -> absl::StatusOr<std::shared_ptr<solid::Solid>> {
    if (edited == nullptr) {
      absl::StatusOr<BuiltSolid> built = BuildSolid(request, limits);
      if (!built.ok()) return built.status();
      return std::move(built->solid);
    }
    absl::StatusOr<std::unique_ptr<solid::Solid>> s =
        sculpt::BuildEdited(*edited, SimThreads(limits.sim_threads));
    if (!s.ok()) return s.status();
    return std::shared_ptr<solid::Solid>(*std::move(s));
  };
}

}  // namespace dynsolid::server
