#include "solver/export/design_export.h"

#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/fem/element_set.h"
#include "solver/io/gltf_writer.h"
#include "solver/io/surface_writers.h"
#include "solver/io/volume_mesh.h"
#include "solver/mesh/boundary.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::exporter {
namespace {

constexpr int kMaxLevel = 6;

// An upper bound on the cells after `level` subdivisions: a cell of k
// corners has k hexahedral children, and a hexahedron 8.
int64_t CellsAt(const mesh::CellComplex& control, int level) {
  if (level == 0) return control.num_cells();
  int64_t corners = 0;
  for (int32_t c = 0; c < control.num_cells(); ++c) {
    corners += static_cast<int64_t>(control.cell_vertices(c).size());
  }
  int64_t cells = corners;
  for (int l = 1; l < level; ++l) cells *= 8;
  return cells;
}

absl::Status CheckPoints(const Points& p, int32_t rows, const char* field) {
  if (p.rows() != rows || p.cols() != 3) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": ", p.rows(), " x ", p.cols(),
                                                   " values for ", rows, " control points"));
  }
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    if (!p.row(i).allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ": control point ", i, " is not finite"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

const char* Extension(Format f) {
  switch (f) {
    case Format::kObj: return "obj";
    case Format::kStl: return "stl";
    case Format::kPly: return "ply";
    case Format::kGlb: return "glb";
    case Format::kVtu: return "vtu";
  }
  return "bin";
}

const char* MediaType(Format f) {
  switch (f) {
    case Format::kObj: return "model/obj";
    case Format::kStl: return "model/stl";
    case Format::kPly: return "application/x-ply";
    case Format::kGlb: return "model/gltf-binary";
    case Format::kVtu: return "application/xml";
  }
  return "application/octet-stream";
}

namespace {

// The request's checks (ExportDesign's errors).
absl::Status CheckInput(const DesignInput& in, const ExportOptions& options) {
  if (in.discretization == nullptr) return absl::InvalidArgumentError("no discretization");
  const scene::Discretization& d = *in.discretization;
  const mesh::CellComplex& control = d.control();
  if (options.level < 0 || options.level > kMaxLevel) {
    return absl::InvalidArgumentError(absl::StrCat("level: ", options.level,
                                                   " is not in [0, ", kMaxLevel, "]"));
  }
  const int64_t cells = CellsAt(control, options.level);
  if (cells > options.max_cells) {
    return absl::InvalidArgumentError(absl::StrCat(
        "level: ", options.level, " subdivisions of this control mesh (", control.num_cells(),
        " cells) give about ", cells, " cells, more than the export limit of ",
        options.max_cells, "; ask for a lower level"));
  }
  RETURN_IF_ERROR(CheckPoints(in.positions, control.num_vertices(), "positions"));
  RETURN_IF_ERROR(CheckPoints(in.rest, control.num_vertices(), "rest"));
  if (!options.color_field.empty() && options.color_field != "displacement" &&
      options.color_field != "displacement_magnitude") {
    return absl::InvalidArgumentError(absl::StrCat(
        "color_field: \"", options.color_field,
        "\" is not a field of an export (displacement, displacement_magnitude)"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<mesh::BoundarySurface> DesignSurface(const DesignInput& in,
                                                    const ExportOptions& options,
                                                    int64_t* cells, int64_t* vertices) {
  RETURN_IF_ERROR(CheckInput(in, options));
  const scene::Discretization& d = *in.discretization;
  ASSIGN_OR_RETURN(subdivision::Hierarchy h,
                   subdivision::Subdivide(d.hierarchy.control, options.level, d.control_sharp,
                                          [](const mesh::CellComplex&) {}));
  const Points x = h.a * in.positions;
  const Points u = h.a * (in.positions - in.rest);
  mesh::BoundarySurface surface = mesh::ExtractBoundary(*h.fine, &x);
  if (cells != nullptr) *cells = h.fine->num_cells();
  if (vertices != nullptr) *vertices = h.fine->num_vertices();
  mesh::VertexField disp{"displacement", 3, {}};
  mesh::VertexField mag{"displacement_magnitude", 1, {}};
  for (int32_t v : surface.mesh_vertex) {
    for (int k = 0; k < 3; ++k) disp.values.push_back(u(v, k));
    mag.values.push_back(u.row(v).norm());
  }
  surface.fields.push_back(std::move(disp));
  surface.fields.push_back(std::move(mag));
  return surface;
}

absl::StatusOr<Exported> ExportDesign(const DesignInput& in, const ExportOptions& options) {
  RETURN_IF_ERROR(CheckInput(in, options));
  const scene::Discretization& d = *in.discretization;
  Exported out;
  const bool volume = options.format == Format::kVtu;
  if (!volume) {
    ASSIGN_OR_RETURN(mesh::BoundarySurface surface,
                     DesignSurface(in, options, &out.cells, &out.vertices));
    out.surface_faces = surface.faces.rows();
    switch (options.format) {
      case Format::kObj:
        RETURN_IF_ERROR(io::ObjBytes(surface, &out.bytes));
        break;
      case Format::kStl:
        RETURN_IF_ERROR(io::StlBinaryBytes(surface, &out.bytes));
        break;
      case Format::kPly:
        RETURN_IF_ERROR(io::PlyBinaryBytes(surface, &out.bytes));
        break;
      case Format::kGlb: {
        io::GlbOptions glb;
        glb.color_field = options.color_field;
        glb.generator = "dynsolid export";
        RETURN_IF_ERROR(io::GlbBytes(surface, glb, &out.bytes));
        break;
      }
      case Format::kVtu:
        break;
    }
    return out;
  }

  // The volume: the control mesh subdivided `level` times, its elements
  // classified.
  fem::ElementSet elements;
  ASSIGN_OR_RETURN(subdivision::Hierarchy h,
                   subdivision::Subdivide(d.hierarchy.control, options.level, d.control_sharp,
                                          [&](const mesh::CellComplex& fine) {
                                            elements = fem::ClassifyElements(fine);
                                          }));
  // (a: fine vertices x control points; the identity at level 0.)
  const mesh::CellComplex& fine = *h.fine;
  out.cells = fine.num_cells();
  out.vertices = fine.num_vertices();
  {
    const Points x = h.a * in.positions;
    const Points u = h.a * (in.positions - in.rest);
    // The FEM nodes: the vertices, then a virtual apex per pyramid cell.
    Points nodes = x, nodes_u = u;
    if (elements.num_virtual_nodes > 0) {
      const subdivision::SparseMatrix nodes_of = fem::NodeMatrix(fine, h.a, elements);
      nodes = nodes_of * in.positions;
      nodes_u = nodes_of * (in.positions - in.rest);
    }
    io::VolumeMesh vm = io::ElementsToVolumeMesh(nodes, elements, h.control_cell, options.level);
    // A point per FEM node (ElementsToVolumeMesh's points).
    io::DataArray disp{"displacement", 3, {}, false};
    io::DataArray mag{"displacement_magnitude", 1, {}, false};
    for (Eigen::Index i = 0; i < vm.points.rows(); ++i) {
      for (int k = 0; k < 3; ++k) disp.values.push_back(nodes_u(i, k));
      mag.values.push_back(nodes_u.row(i).norm());
    }
    vm.point_data.push_back(std::move(disp));
    vm.point_data.push_back(std::move(mag));
    RETURN_IF_ERROR(io::VtuBytes(vm, &out.bytes));
  }
  return out;
}

}  // namespace dynsolid::exporter
