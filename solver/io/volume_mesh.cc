#include "solver/io/volume_mesh.h"

#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <string_view>

#include "solver/common/status_macros.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace {

using internal::OutputFile;

constexpr uint8_t kVtkPolyhedron = 42;

std::string XmlEscape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out.push_back(c);
    }
  }
  return out;
}

absl::Status CheckArrays(const std::string& path, std::string_view where,
                         const std::vector<DataArray>& arrays, int64_t tuples) {
  std::set<std::string> names;
  for (const DataArray& a : arrays) {
    if (a.name.empty()) {
      return absl::InvalidArgumentError(internal::Cat(path, ": ", where, " array with no name"));
    }
    if (!names.insert(a.name).second) {
      return absl::InvalidArgumentError(
          internal::Cat(path, ": ", where, " array '", a.name, "' appears twice"));
    }
    if (a.components < 1 ||
        a.values.size() != static_cast<size_t>(tuples) * static_cast<size_t>(a.components)) {
      return absl::InvalidArgumentError(
          internal::Cat(path, ": ", where, " array '", a.name, "' has ", a.values.size(),
                        " values: expected ", tuples, " tuples x ", a.components, " components"));
    }
    for (size_t i = 0; i < a.values.size(); ++i) {
      const double v = a.values[i];
      if (!std::isfinite(v)) {
        return absl::InvalidArgumentError(
            internal::Cat(path, ": ", where, " array '", a.name, "' value ", i, " is not finite"));
      }
      if (a.integer && (v != std::floor(v) || v < std::numeric_limits<int32_t>::min() ||
                        v > std::numeric_limits<int32_t>::max())) {
        return absl::InvalidArgumentError(internal::Cat(path, ": ", where, " array '", a.name,
                                                        "' value ", i, " = ", v,
                                                        " is not a 32-bit integer"));
      }
    }
  }
  return absl::OkStatus();
}

absl::Status CheckMesh(const std::string& path, const VolumeMesh& m) {
  const int64_t np = m.points.rows();
  const int64_t nc = static_cast<int64_t>(m.types.size());
  if (static_cast<int64_t>(m.offsets.size()) != nc) {
    return absl::InvalidArgumentError(
        internal::Cat(path, ": ", m.offsets.size(), " offsets: expected one per cell, ", nc));
  }
  int64_t previous = 0;
  for (int64_t c = 0; c < nc; ++c) {
    if (m.types[c] == kVtkPolyhedron) {
      return absl::InvalidArgumentError(
          internal::Cat(path, ": cell ", c, " is a polyhedron (42): not supported by VolumeMesh"));
    }
    if (m.offsets[c] < previous) {
      return absl::InvalidArgumentError(internal::Cat(path, ": offsets decrease at cell ", c));
    }
    previous = m.offsets[c];
  }
  if (previous != static_cast<int64_t>(m.connectivity.size())) {
    return absl::InvalidArgumentError(internal::Cat(path, ": the last offset is ", previous,
                                                    ": expected the connectivity size ",
                                                    m.connectivity.size()));
  }
  for (size_t i = 0; i < m.connectivity.size(); ++i) {
    if (m.connectivity[i] < 0 || m.connectivity[i] >= np) {
      return absl::InvalidArgumentError(internal::Cat(
          path, ": connectivity entry ", i, " is ", m.connectivity[i], ": expected 0 to ", np - 1));
    }
  }
  for (Eigen::Index i = 0; i < m.points.rows(); ++i) {
    if (!m.points.row(i).allFinite()) {
      return absl::InvalidArgumentError(internal::Cat(path, ": point ", i, " is not finite"));
    }
  }
  RETURN_IF_ERROR(CheckArrays(path, "cell data", m.cell_data, nc));
  return CheckArrays(path, "point data", m.point_data, np);
}

void WriteArray(OutputFile& out, const DataArray& a) {
  out.Put("        <DataArray type=\"")
      .Put(a.integer ? "Int32" : "Float64")
      .Put("\" Name=\"")
      .Put(XmlEscape(a.name))
      .Put("\" NumberOfComponents=\"")
      .Put(static_cast<int64_t>(a.components))
      .Put("\" format=\"ascii\">\n");
  const size_t tuples = a.values.size() / static_cast<size_t>(a.components);
  for (size_t t = 0; t < tuples; ++t) {
    out.Put("         ");
    for (int k = 0; k < a.components; ++k) {
      const double v = a.values[t * a.components + k];
      out.Put(' ');
      if (a.integer) {
        out.Put(static_cast<int64_t>(v));
      } else {
        out.Put(v);
      }
    }
    out.Put('\n');
  }
  out.Put("        </DataArray>\n");
}

}  // namespace

namespace {

absl::Status PutVtu(OutputFile& out, const VolumeMesh& mesh);

}  // namespace

absl::Status WriteVtu(const std::string& path, const VolumeMesh& mesh) {
  RETURN_IF_ERROR(CheckMesh(path, mesh));
  OutputFile out(path);
  if (!out.ok()) return out.status();
  return PutVtu(out, mesh);
}

absl::Status VtuBytes(const VolumeMesh& mesh, std::string* bytes) {
  RETURN_IF_ERROR(CheckMesh("vtu", mesh));
  std::string made;
  OutputFile out(&made);
  RETURN_IF_ERROR(PutVtu(out, mesh));
  bytes->append(made);
  return absl::OkStatus();
}

namespace {

absl::Status PutVtu(OutputFile& out, const VolumeMesh& mesh) {
  const int64_t np = mesh.points.rows();
  const int64_t nc = static_cast<int64_t>(mesh.types.size());
  out.Put("<?xml version=\"1.0\"?>\n");
  out.Put(
      "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\">\n");
  out.Put("  <UnstructuredGrid>\n");
  out.Put("    <Piece NumberOfPoints=\"").Put(np).Put("\" NumberOfCells=\"").Put(nc).Put("\">\n");
  out.Put("      <PointData>\n");
  for (const DataArray& a : mesh.point_data) WriteArray(out, a);
  out.Put("      </PointData>\n");
  out.Put("      <CellData>\n");
  for (const DataArray& a : mesh.cell_data) WriteArray(out, a);
  out.Put("      </CellData>\n");
  out.Put("      <Points>\n");
  out.Put(
      "        <DataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\" "
      "format=\"ascii\">\n");
  for (Eigen::Index i = 0; i < mesh.points.rows(); ++i) {
    out.Put("          ")
        .Put(mesh.points(i, 0))
        .Put(' ')
        .Put(mesh.points(i, 1))
        .Put(' ')
        .Put(mesh.points(i, 2))
        .Put('\n');
  }
  out.Put("        </DataArray>\n");
  out.Put("      </Points>\n");
  out.Put("      <Cells>\n");
  out.Put("        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
  int64_t begin = 0;
  for (int64_t c = 0; c < nc; ++c) {
    out.Put("         ");
    for (int64_t i = begin; i < mesh.offsets[c]; ++i) out.Put(' ').Put(mesh.connectivity[i]);
    out.Put('\n');
    begin = mesh.offsets[c];
  }
  out.Put("        </DataArray>\n");
  out.Put("        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
  for (int64_t c = 0; c < nc; ++c) out.Put("          ").Put(mesh.offsets[c]).Put('\n');
  out.Put("        </DataArray>\n");
  out.Put("        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (int64_t c = 0; c < nc; ++c) {
    out.Put("          ").Put(static_cast<int64_t>(mesh.types[c])).Put('\n');
  }
  out.Put("        </DataArray>\n");
  out.Put("      </Cells>\n");
  out.Put("    </Piece>\n");
  out.Put("  </UnstructuredGrid>\n");
  out.Put("</VTKFile>\n");
  return out.Close();
}

}  // namespace

VolumeMesh ElementsToVolumeMesh(const Points& nodes, const fem::ElementSet& elements,
                                std::span<const int32_t> cell_control_cell, int level) {
  constexpr uint8_t kVtkHexahedron = 12;
  constexpr uint8_t kVtkPyramid = 14;
  // VTK hexahedron corners as tensor offsets (a, b, c) in {0,1}^3 of (i, j, k).
  constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                 {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  VolumeMesh m;
  m.points = nodes;
  const int32_t nc = elements.num_cubic() + elements.num_linear() + elements.num_pyramid();
  m.types.reserve(nc);
  m.offsets.reserve(nc);
  m.connectivity.reserve(8 * static_cast<size_t>(elements.num_cubic() + elements.num_linear()) +
                         5 * static_cast<size_t>(elements.num_pyramid()));
  DataArray kind{"element_kind", 1, {}, true};
  DataArray cell{"cell", 1, {}, true};
  DataArray control{"control_cell", 1, {}, true};
  DataArray level_array{"level", 1, std::vector<double>(nc, static_cast<double>(level)), true};
  kind.values.reserve(nc);
  cell.values.reserve(nc);
  control.values.reserve(nc);
  auto add_data = [&](fem::ElementKind k, int32_t c) {
    kind.values.push_back(static_cast<double>(static_cast<uint8_t>(k)));
    cell.values.push_back(c);
    int32_t cc = c;
    if (!cell_control_cell.empty()) {
      cc = c >= 0 && static_cast<size_t>(c) < cell_control_cell.size() ? cell_control_cell[c] : -1;
    }
    control.values.push_back(cc);
  };
  for (int32_t e = 0; e < elements.num_cubic(); ++e) {
    const int32_t* n = elements.cubic_nodes.data() + static_cast<size_t>(e) * fem::kCubicNodes;
    for (const auto& corner : kCorner) {
      const int i = 1 + corner[0], j = 1 + corner[1], k = 1 + corner[2];
      m.connectivity.push_back(n[16 * i + 4 * j + k]);
    }
    m.types.push_back(kVtkHexahedron);
    m.offsets.push_back(static_cast<int64_t>(m.connectivity.size()));
    add_data(fem::ElementKind::kCubic, elements.cubic_cell[e]);
  }
  for (int32_t e = 0; e < elements.num_linear(); ++e) {
    const int32_t* n = elements.linear_nodes.data() + static_cast<size_t>(e) * fem::kLinearNodes;
    m.connectivity.insert(m.connectivity.end(), n, n + fem::kLinearNodes);
    m.types.push_back(kVtkHexahedron);
    m.offsets.push_back(static_cast<int64_t>(m.connectivity.size()));
    add_data(fem::ElementKind::kLinear, elements.linear_cell[e]);
  }
  for (int32_t e = 0; e < elements.num_pyramid(); ++e) {
    const int32_t* n = elements.pyramid_nodes.data() + static_cast<size_t>(e) * fem::kPyramidNodes;
    m.connectivity.insert(m.connectivity.end(), n, n + fem::kPyramidNodes);
    m.types.push_back(kVtkPyramid);
    m.offsets.push_back(static_cast<int64_t>(m.connectivity.size()));
    add_data(fem::ElementKind::kPyramid, elements.pyramid_cell[e]);
  }
  m.cell_data = {std::move(kind), std::move(cell), std::move(control), std::move(level_array)};
  return m;
}

}  // namespace dynsolid::io
