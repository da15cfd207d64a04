#include "solver/tools/sim_report.h"

#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "solver/common/json_writer.h"
#include "solver/common/status_macros.h"
#include "solver/io/surface_writers.h"
#include "solver/io/volume_mesh.h"
#include "solver/mesh/boundary.h"

namespace dynsolid::tools {

std::string StatsJson(const scene::Discretization& d, const scene::BuildTimings& t,
                      const std::string& origin) {
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
  j.Add("steps", 0);
  return j.Finish();
}

absl::Status WriteOutputs(const scene::Discretization& d, const scene::BuildTimings& t,
                          const std::string& origin, const std::string& dir) {
  const Points nodes = d.node_matrix * d.control().positions();
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
  out << StatsJson(d, t, origin);
  if (!out) return absl::InternalError(absl::StrCat("cannot write ", dir, "/stats.json"));
  return absl::OkStatus();
}

}  // namespace dynsolid::tools
