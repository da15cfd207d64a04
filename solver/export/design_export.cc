#include "solver/export/design_export.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/fem/element_data.h"
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

// The control cell of each element, kinds in order (the VTU's cells).
std::vector<int32_t> CellsOfVolume(const fem::ElementSet& el, const std::vector<int32_t>& control) {
  std::vector<int32_t> out;
  for (const std::vector<int32_t>* cells : {&el.cubic_cell, &el.linear_cell, &el.pyramid_cell}) {
    for (int32_t fine : *cells) out.push_back(control.empty() ? fine : control[fine]);
  }
  return out;
}

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

absl::StatusOr<MaterialFields> MaterialFieldsOf(const scene::Discretization& d,
                                                const Design& design) {
  const fem::ElementSet& el = d.elements;
  const std::array<int32_t, 3> counts{el.num_cubic(), el.num_linear(), el.num_pyramid()};
  const std::array<const std::vector<int32_t>*, 3> cells{&el.cubic_cell, &el.linear_cell,
                                                         &el.pyramid_cell};
  const int32_t total = counts[0] + counts[1] + counts[2];
  const int32_t ncc = d.control().num_cells();
  MaterialFields out;
  out.level = d.hierarchy.levels;
  out.young.assign(total, 0.0);
  out.density.assign(total, 0.0);
  out.plastic.assign(total, 0.0);
  out.cell_young.assign(ncc, 0.0);
  out.cell_density.assign(ncc, 0.0);
  out.cell_plastic.assign(ncc, 0.0);
  std::vector<int64_t> cell_samples(ncc, 0);
  std::vector<int32_t> control(total);  // element -> control cell
  for (int kind = 0, e0 = 0; kind < fem::kElementKinds; e0 += counts[kind], ++kind) {
    for (int32_t e = 0; e < counts[kind]; ++e) {
      const int32_t fine = (*cells[kind])[e];
      control[e0 + e] = d.hierarchy.control_cell.empty() ? fine : d.hierarchy.control_cell[fine];
    }
  }
  // The samples: run-length pairs over every element's quadrature points.
  int kind = 0, e = 0, q = 0, index = 0;
  int points = fem::MakeKindTable(fem::ElementKind::kCubic).points;
  auto next_element = [&] {
    ++index;
    ++e;
    q = 0;
    while (kind < fem::kElementKinds && e >= counts[kind]) {
      e = 0;
      if (++kind < fem::kElementKinds) points = fem::MakeKindTable(static_cast<fem::ElementKind>(kind)).points;
    }
  };
  while (kind < fem::kElementKinds && counts[kind] == 0) {
    if (++kind < fem::kElementKinds) points = fem::MakeKindTable(static_cast<fem::ElementKind>(kind)).points;
  }
  for (int i = 0; i + 1 < design.sample_runs_size(); i += 2) {
    const int32_t m = design.sample_runs(i + 1);
    if (m < 0 || m >= design.materials_size()) {
      return absl::InvalidArgumentError(absl::StrCat("design.sample_runs[", i + 1, "] out of range"));
    }
    const Design::Sample& sample = design.materials(m);
    for (int32_t r = 0; r < design.sample_runs(i); ++r) {
      if (kind >= fem::kElementKinds) return absl::InvalidArgumentError("design.sample_runs: more samples than elements");
      out.young[index] += sample.young_modulus() / points;
      out.density[index] += sample.density() / points;
      out.cell_young[control[index]] += sample.young_modulus();
      out.cell_density[control[index]] += sample.density();
      ++cell_samples[control[index]];
      if (++q == points) next_element();
    }
  }
  if (kind < fem::kElementKinds) return absl::InvalidArgumentError("design.sample_runs: fewer samples than elements");
  for (int32_t c = 0; c < ncc; ++c) {
    if (cell_samples[c] == 0) continue;
    out.cell_young[c] /= static_cast<double>(cell_samples[c]);
    out.cell_density[c] /= static_cast<double>(cell_samples[c]);
  }
  // Plastic strain per flow unit: a control cell's, or an element's.
  const int units = design.plastic_strain_size();
  if (units == ncc) {
    for (int32_t c = 0; c < ncc; ++c) out.cell_plastic[c] = design.plastic_strain(c);
    for (int32_t x = 0; x < total; ++x) out.plastic[x] = out.cell_plastic[control[x]];
  } else if (units == total) {
    for (int32_t x = 0; x < total; ++x) {
      out.plastic[x] = design.plastic_strain(x);
      out.cell_plastic[control[x]] = std::max(out.cell_plastic[control[x]], out.plastic[x]);
    }
  } else if (units != 0) {
    return absl::InvalidArgumentError(absl::StrCat("design.plastic_strain: ", units,
                                                   " units, neither the control cells nor the elements"));
  }
  return out;
}

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
    // Cell data: the strain between the cell's nodes, and the materials.
    const Points nodes_rest = nodes - nodes_u;
    io::DataArray strain{"strain", 1, {}, false};
    const int64_t nvc = static_cast<int64_t>(vm.types.size());
    strain.values.reserve(nvc);
    for (int64_t c = 0, begin = 0; c < nvc; begin = vm.offsets[c], ++c) {
      double worst = 0;
      for (int64_t i = begin; i < vm.offsets[c]; ++i) {
        for (int64_t j = i + 1; j < vm.offsets[c]; ++j) {
          const int64_t a = vm.connectivity[i], b = vm.connectivity[j];
          const double l0 = (nodes_rest.row(a) - nodes_rest.row(b)).norm();
          if (l0 > 0) worst = std::max(worst, std::abs((nodes.row(a) - nodes.row(b)).norm() / l0 - 1));
        }
      }
      strain.values.push_back(worst);
    }
    vm.cell_data.push_back(std::move(strain));
    if (in.materials != nullptr) {
      const MaterialFields& mf = *in.materials;
      const bool own = options.level == mf.level &&
                       static_cast<int64_t>(mf.young.size()) == nvc;
      io::DataArray young{"young_modulus", 1, {}, false};
      io::DataArray density{"density", 1, {}, false};
      io::DataArray plastic{"plastic_strain", 1, {}, false};
      const std::vector<int32_t> cell_of = CellsOfVolume(elements, h.control_cell);
      for (int64_t c = 0; c < nvc; ++c) {
        const int32_t cc = cell_of[c];
        const bool in_range = cc >= 0 && cc < static_cast<int32_t>(mf.cell_young.size());
        young.values.push_back(own ? mf.young[c] : in_range ? mf.cell_young[cc] : 0.0);
        density.values.push_back(own ? mf.density[c] : in_range ? mf.cell_density[cc] : 0.0);
        plastic.values.push_back(own ? mf.plastic[c] : in_range ? mf.cell_plastic[cc] : 0.0);
      }
      vm.cell_data.push_back(std::move(young));
      vm.cell_data.push_back(std::move(density));
      vm.cell_data.push_back(std::move(plastic));
    }
    RETURN_IF_ERROR(io::VtuBytes(vm, &out.bytes));
  }
  return out;
}

}  // namespace dynsolid::exporter
