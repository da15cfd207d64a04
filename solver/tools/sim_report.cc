#include "solver/tools/sim_report.h"

#include <filesystem>
#include <algorithm>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "solver/common/json_writer.h"
#include "solver/common/status_macros.h"
#include "solver/io/surface_writers.h"
#include "solver/io/volume_mesh.h"
#include "solver/mesh/boundary.h"

namespace dynsolid::tools {

std::string StatsJson(const scene::Discretization& d, const scene::BuildTimings& t,
                      const std::string& origin, const RunRecord& run) {
  const auto& e = d.elements;
  const double cells = static_cast<double>(d.fine().num_cells());
  const auto boundary = d.fine().CountBoundary();
  JsonWriter j;
  j.Add("scene", d.name)
      .Add("origin", origin)
      .Add("control_cells", d.control().num_cells())
      .Add("control_vertices", d.control().num_vertices())
      .Add("input_cells", d.input_cells)
      .Add("locally_refined_cells", d.locally_refined_cells)
      .Add("sharp_control_edges", d.sharp_control_edges)
      .Add("levels", d.hierarchy.levels)
      .Add("cells", d.fine().num_cells())
      .Add("vertices", d.fine().num_vertices())
      .Add("nodes", e.num_nodes())
      .Add("virtual_nodes", e.num_virtual_nodes)
      .Add("faces", d.fine().num_faces())
      .Add("edges", d.fine().num_edges());
  j.Begin("elements")
      .Add("cubic", e.num_cubic())
      .Add("linear", e.num_linear())
      .Add("pyramid", e.num_pyramid())
      .Add("pyramid_cells", e.num_pyramid_cells())
      .End();
  // Table 1's %BE / %LE / %PE: the share of level-L cells of each kind.
  j.Begin("fractions_percent")
      .Add("cubic", 100.0 * e.num_cubic() / cells)
      .Add("linear", 100.0 * e.num_linear() / cells)
      .Add("pyramid", 100.0 * e.num_pyramid_cells() / cells)
      .End();
  j.Begin("boundary")
      .Add("vertices", boundary.vertices)
      .Add("edges", boundary.edges)
      .Add("faces", boundary.faces)
      .Add("euler_characteristic", boundary.euler())
      .End();
  j.Add("node_matrix_nonzeros", static_cast<int64_t>(d.node_matrix.nonZeros()));
  j.Begin("timings_ms")
      .Add("load", t.load_ms)
      .Add("validate", t.validate_ms)
      .Add("local_refine", t.local_refine_ms)
      .Add("subdivide", t.subdivide_ms)
      .Add("classify", t.classify_ms)
      .End();
  const int64_t steps = static_cast<int64_t>(run.step_ms.size());
  j.Add("steps", steps);
  if (run.build != nullptr) {
    const solid::BuildReport& b = *run.build;
    j.Begin("dynamics")
        .Add("model", run.model)
        .Add("integrator", run.integrator)
        .Add("element_products", run.element_products)
        .Add("time_step", run.time_step)
        .Add("total_mass", run.total_mass)
        .Add("rest_volume", run.rest_volume)
        .Add("omega_max", b.omega_max)
        .Add("stable_step", b.stable_step)
        .Add("stable_step_passes", b.stable_step_passes)
        .Add("substeps_estimated", b.substeps)
        .Add("substeps", run.final_substeps)
        .Add("rollbacks", run.rollbacks)
        .Add("damping_matrix", b.damping_matrix)
        .Add("cubic_groups", b.cubic_groups)
        .Add("linear_groups", b.linear_groups)
        .Add("pyramid_groups", b.pyramid_groups)
        .Add("material_arrays", b.material_arrays)
        .Add("fixed_control_points", b.fixed_control_points)
        .Add("penalty_springs", b.penalty_springs)
        .Add("point_forces", b.point_forces)
        .Add("gravity", b.gravity)
        .Add("bytes_per_element", b.element_bytes)
        .Add("shared_matrix_bytes", b.shared_matrix_bytes)
        .Add("node_matrix_bytes", b.node_matrix_bytes)
        .Add("node_matrix_float_values", b.node_matrix_float_values)
        .Add("factorized_elements", b.factorized_elements)
        .Add("quadrature_elements", b.quadrature_elements)
        .Add("corotated_cells", b.corotated_cells)
        .Add("cell_matrices", b.cell_matrices)
        .Add("cell_matrix_bytes", b.cell_matrix_bytes)
        .Add("measure_quad_path", b.measure_quad_path)
        .Add("build_ms", b.build_ms)
        .End();
  }
  if (steps > 0) {
    const double ms = Median(run.step_ms);
    j.Add("ms_per_step", ms);
    j.Add("steps_per_second", ms > 0 ? 1000.0 / ms : 0.0);
    j.Add("simulated_seconds_per_second", ms > 0 ? run.time_step / (ms / 1000.0) : 0.0);
    // Per-phase medians; phases the scene does not use (-1) are left out.
    j.Begin("phases_ms");
    auto phase = [&](const char* name, double solid::PhaseTimes::*field) {
      std::vector<double> v;
      for (const auto& p : run.phases) {
        if (p.*field >= 0) v.push_back(p.*field);
      }
      if (!v.empty()) j.Add(name, Median(v));
    };
    phase("nodes", &solid::PhaseTimes::nodes);
    phase("measure", &solid::PhaseTimes::measure);
    phase("stiffness", &solid::PhaseTimes::stiffness);
    phase("project", &solid::PhaseTimes::project);
    phase("loads", &solid::PhaseTimes::loads);
    phase("damping", &solid::PhaseTimes::damping);
    phase("solve", &solid::PhaseTimes::solve);
    j.End();
    double sum = 0;
    for (int32_t c : run.cg_iterations) sum += c;
    j.Begin("cg_iterations")
        .Add("mean_per_step", sum / static_cast<double>(steps))
        .Add("max_single_solve", run.cg_max)
        .End();
    j.Begin("energy_j")
        .Add("kinetic", run.energies.kinetic)
        .Add("strain", run.energies.strain)
        .Add("springs", run.energies.springs)
        .End();
  }
  return j.Finish();
}

absl::Status WriteFrame(const scene::Discretization& d, const Points& p, const std::string& dir,
                        const std::string& name) {
  const Points nodes = d.node_matrix * p;
  const Points vertices = nodes.topRows(d.fine().num_vertices());
  const mesh::BoundarySurface surface = mesh::ExtractBoundary(d.fine(), &vertices);
  RETURN_IF_ERROR(io::WriteObj(dir + "/" + name + ".obj", surface));
  const io::VolumeMesh volume =
      io::ElementsToVolumeMesh(nodes, d.elements, d.hierarchy.control_cell, d.hierarchy.levels);
  return io::WriteVtu(dir + "/" + name + ".vtu", volume);
}

absl::Status WriteOutputs(const scene::Discretization& d, const scene::BuildTimings& t,
                          const std::string& origin, const RunRecord& run,
                          const Points& control_positions, const std::string& dir) {
  const Points nodes = d.node_matrix * control_positions;
  const Points vertices = nodes.topRows(d.fine().num_vertices());
  mesh::BoundarySurface surface = mesh::ExtractBoundary(d.fine(), &vertices);

  // Per boundary vertex: the element kind of the cell of its first face.
  std::vector<int> cell_kind(d.fine().num_cells(), 0);
  for (int32_t c : d.elements.linear_cell) cell_kind[c] = 1;
  for (int32_t c : d.elements.pyramid_cell) cell_kind[c] = 2;
  mesh::VertexField kind{"element_kind", 1,
                         std::vector<double>(surface.mesh_vertex.size(), -1.0)};
  for (int32_t f = 0; f < surface.faces.rows(); ++f) {
    const int32_t cell = d.fine().face_cells(surface.mesh_face[f])[0];
    for (int32_t v : surface.faces.row(f)) {
      if (kind.values[v] < 0) kind.values[v] = cell_kind[cell];
    }
  }
  surface.fields.push_back(std::move(kind));

  const io::VolumeMesh volume =
      io::ElementsToVolumeMesh(nodes, d.elements, d.hierarchy.control_cell, d.hierarchy.levels);

  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return absl::PermissionDeniedError(
        absl::StrCat("cannot create output folder ", dir, ": ", ec.message()));
  }
  RETURN_IF_ERROR(io::WriteObj(dir + "/boundary.obj", surface));
  RETURN_IF_ERROR(io::WritePly(dir + "/boundary.ply", surface));
  RETURN_IF_ERROR(io::WriteVtu(dir + "/volume.vtu", volume));
  std::ofstream out(dir + "/stats.json");
  out << StatsJson(d, t, origin, run);
  if (!out) return absl::InternalError(absl::StrCat("cannot write ", dir, "/stats.json"));
  return absl::OkStatus();
}

}  // namespace dynsolid::tools
