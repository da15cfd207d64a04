// VTK legacy ASCII reader for unstructured grids. Token-based: VTK writers
// wrap values across lines freely; each token remembers its line.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "solver/common/status_macros.h"
#include "solver/io/cell_shapes.h"
#include "solver/io/mesh_readers.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace {

using internal::ParseDouble;
using internal::ParseInt64;
using internal::Quote;
using internal::SafeReserve;
using internal::Shape;
using internal::TextFile;
using internal::TokenCursor;

constexpr int64_t kMaxCount = std::numeric_limits<int32_t>::max();

// VTK cell types (vtkCellType.h).
constexpr int kVtkTetra = 10;
constexpr int kVtkVoxel = 11;
constexpr int kVtkHexahedron = 12;
constexpr int kVtkWedge = 13;
constexpr int kVtkPyramid = 14;
constexpr int kVtkPolyhedron = 42;

const char* VtkTypeName(int64_t type) {
  switch (type) {
    case 15:
      return "pentagonal prism";
    case 16:
      return "hexagonal prism";
    case 21:
      return "quadratic edge";
    case 22:
      return "quadratic triangle";
    case 23:
      return "quadratic quad";
    case 24:
      return "quadratic tetra";
    case 25:
      return "quadratic hexahedron";
    case 26:
      return "quadratic wedge";
    case 27:
      return "quadratic pyramid";
    case 28:
      return "biquadratic quad";
    case 29:
      return "triquadratic hexahedron";
    case 41:
      return "convex point set";
    default:
      break;
  }
  if (type >= 60 && type <= 67) return "higher-order cell";
  if (type >= 68 && type <= 74) return "Lagrange cell";
  if (type >= 75 && type <= 81) return "Bezier cell";
  return nullptr;
}

bool KeywordIs(std::string_view token, std::string_view keyword) {
  return internal::EqualsIgnoreCase(token, keyword);
}

class VtkParser {
 public:
  explicit VtkParser(const TextFile& file) : file_(file), cursor_(file) {}

  absl::StatusOr<mesh::MeshInput> Parse() {
    RETURN_IF_ERROR(ParseHeader());
    std::string_view token;
    if (!cursor_.Next(&token)) {
      return cursor_.Error("unexpected end of file: expected 'DATASET UNSTRUCTURED_GRID'");
    }
    if (!KeywordIs(token, "DATASET")) {
      return cursor_.Error(
          internal::Cat("expected 'DATASET UNSTRUCTURED_GRID', found ", Quote(token)));
    }
    if (!cursor_.Next(&token)) {
      return cursor_.Error("unexpected end of file: expected UNSTRUCTURED_GRID after DATASET");
    }
    if (!KeywordIs(token, "UNSTRUCTURED_GRID")) {
      return cursor_.Error(
          internal::Cat("unsupported DATASET ", Quote(token), ": expected UNSTRUCTURED_GRID"));
    }
    while (cursor_.Next(&token)) {
      if (KeywordIs(token, "POINTS")) {
        RETURN_IF_ERROR(ParsePoints());
      } else if (KeywordIs(token, "CELLS")) {
        RETURN_IF_ERROR(ParseCells());
      } else if (KeywordIs(token, "CELL_TYPES")) {
        RETURN_IF_ERROR(ParseCellTypes());
      } else if (KeywordIs(token, "METADATA")) {
        cursor_.SkipPastBlankLine();
      } else if (KeywordIs(token, "FIELD")) {
        RETURN_IF_ERROR(SkipField());
      } else if (KeywordIs(token, "CELL_DATA") || KeywordIs(token, "POINT_DATA")) {
        break;  // attributes: everything needed has been read
      } else {
        return cursor_.Error(internal::Cat(
            "unexpected keyword ", Quote(token),
            " in the UNSTRUCTURED_GRID: expected POINTS, CELLS, CELL_TYPES, FIELD, METADATA, "
            "CELL_DATA or POINT_DATA"));
      }
    }
    if (points_line_ == 0)
      return cursor_.Error("no POINTS section: expected POINTS n float|double");
    if (cells_line_ == 0) return cursor_.Error("no CELLS section: expected CELLS");
    if (types_line_ == 0) return cursor_.Error("no CELL_TYPES section: expected CELL_TYPES n");
    return BuildCells();
  }

 private:
  absl::Status ParseHeader() {
    if (internal::Trim(file_.contents()).empty()) {
      return file_.Error(1, "empty file: expected '# vtk DataFile Version x.x'");
    }
    const std::string_view first = internal::Trim(cursor_.RestOfLine());
    constexpr std::string_view kMagic = "# vtk DataFile Version";
    if (first.size() < kMagic.size() ||
        !internal::EqualsIgnoreCase(first.substr(0, kMagic.size()), kMagic)) {
      return file_.Error(
          1, internal::Cat("expected '# vtk DataFile Version x.x' (a VTK legacy file), found ",
                           Quote(first)));
    }
    cursor_.RestOfLine();  // line 2: title
    const std::string_view format = internal::Trim(cursor_.RestOfLine());
    if (KeywordIs(format, "BINARY")) {
      return file_.Error(
          3,
          "binary VTK file: only ASCII VTK legacy files are read; save as ASCII "
          "(e.g. 'meshio convert --ascii in.vtk out.vtk', or ParaView's ASCII file type)");
    }
    if (!KeywordIs(format, "ASCII")) {
      return file_.Error(
          3, internal::Cat("expected ASCII or BINARY on line 3, found ", Quote(format)));
    }
    return absl::OkStatus();
  }

  // Next token or an "unexpected end of file in <section>: expected ..." error.
  absl::Status Need(std::string_view* token, std::string_view section, int64_t expected,
                    int64_t got, std::string_view noun) {
    if (cursor_.Next(token)) return absl::OkStatus();
    return cursor_.Error(internal::Cat("unexpected end of file in ", section, ": expected ",
                                       expected, " ", noun, ", got ", got));
  }

  absl::StatusOr<int64_t> Count(std::string_view token, std::string_view what) {
    int64_t v;
    if (!ParseInt64(token, &v) || v < 0) {
      return cursor_.Error(internal::Cat("bad number ", Quote(token), " for ", what,
                                         ": expected a non-negative integer"));
    }
    if (v > kMaxCount) {
      return cursor_.Error(internal::Cat(what, " ", v, " is too large: at most ", kMaxCount));
    }
    return v;
  }

  absl::Status ParsePoints() {
    if (points_line_ != 0) return cursor_.Error("second POINTS section: expected only one");
    points_line_ = cursor_.line();
    std::string_view token;
    RETURN_IF_ERROR(Need(&token, "POINTS", 1, 0, "point count"));
    ASSIGN_OR_RETURN(num_points_, Count(token, "the number of POINTS"));
    RETURN_IF_ERROR(Need(&token, "POINTS", 1, 0, "data type"));
    if (!KeywordIs(token, "float") && !KeywordIs(token, "double")) {
      return cursor_.Error(internal::Cat("unsupported POINTS data type ", Quote(token),
                                         ": expected float or double"));
    }
    const int64_t n = 3 * num_points_;
    coords_.reserve(SafeReserve(n, cursor_.remaining_bytes(), 2));
    static constexpr const char* kAxis[3] = {"x", "y", "z"};
    for (int64_t i = 0; i < n; ++i) {
      RETURN_IF_ERROR(Need(&token, "POINTS", num_points_, i / 3, "points"));
      double v;
      if (!ParseDouble(token, &v)) {
        return cursor_.Error(internal::Cat("bad number ", Quote(token), " for the ", kAxis[i % 3],
                                           " coordinate of point ", i / 3, ": expected a number"));
      }
      if (!std::isfinite(v)) {
        return cursor_.Error(internal::Cat("coordinate ", Quote(token), " (", kAxis[i % 3],
                                           ") of point ", i / 3, " is not finite"));
      }
      coords_.push_back(v);
    }
    return absl::OkStatus();
  }

  // Reads `n` integers of `section` into `out`, remembering in `lines` the
  // line of every value when given.
  absl::Status ReadIntegers(int64_t n, std::string_view section, std::string_view noun,
                            std::vector<int64_t>& out) {
    out.reserve(SafeReserve(n, cursor_.remaining_bytes(), 2));
    std::string_view token;
    for (int64_t i = 0; i < n; ++i) {
      RETURN_IF_ERROR(Need(&token, section, n, i, noun));
      int64_t v;
      if (!ParseInt64(token, &v)) {
        return cursor_.Error(
            internal::Cat("bad number ", Quote(token), " in ", section, ": expected an integer"));
      }
      out.push_back(v);
    }
    return absl::OkStatus();
  }

  absl::Status ParseCells() {
    if (cells_line_ != 0) return cursor_.Error("second CELLS section: expected only one");
    cells_line_ = cursor_.line();
    std::string_view token;
    RETURN_IF_ERROR(Need(&token, "CELLS", 2, 0, "counts"));
    ASSIGN_OR_RETURN(const int64_t a, Count(token, "the first CELLS count"));
    RETURN_IF_ERROR(Need(&token, "CELLS", 2, 1, "counts"));
    ASSIGN_OR_RETURN(const int64_t b, Count(token, "the second CELLS count"));
    // The 5.1 layout announces itself with OFFSETS; peek at the next token.
    TokenCursor saved = cursor_;
    if (cursor_.Next(&token) && KeywordIs(token, "OFFSETS")) return ParseCells51(a, b);
    cursor_ = saved;
    return ParseCellsClassic(a, b);
  }

  // "CELLS n size", then n lists "count id...": size = n + sum of counts.
  absl::Status ParseCellsClassic(int64_t n, int64_t size) {
    offsets_.reserve(SafeReserve(n, cursor_.remaining_bytes(), 4) + 1);
    offsets_.push_back(0);
    cell_lines_.reserve(SafeReserve(n, cursor_.remaining_bytes(), 4));
    connectivity_.reserve(SafeReserve(size - n, cursor_.remaining_bytes(), 2));
    std::string_view token;
    int64_t used = 0;
    for (int64_t c = 0; c < n; ++c) {
      RETURN_IF_ERROR(Need(&token, "CELLS", n, c, "cells"));
      cell_lines_.push_back(cursor_.line());
      ASSIGN_OR_RETURN(const int64_t count,
                       Count(token, internal::Cat("the point count of cell ", c)));
      used += 1 + count;
      if (used > size) {
        return cursor_.Error(
            internal::Cat("CELLS lists more than the declared size ", size, " at cell ", c));
      }
      for (int64_t i = 0; i < count; ++i) {
        RETURN_IF_ERROR(Need(&token, "CELLS", n, c, "cells"));
        int64_t v;
        if (!ParseInt64(token, &v)) {
          return cursor_.Error(internal::Cat("bad number ", Quote(token), " in cell ", c,
                                             " of CELLS: expected an integer"));
        }
        connectivity_.push_back(v);
      }
      offsets_.push_back(static_cast<int64_t>(connectivity_.size()));
    }
    if (used != size) {
      return cursor_.Error(internal::Cat("CELLS declares size ", size, " but its ", n,
                                         " cells hold ", used, " values"));
    }
    return absl::OkStatus();
  }

  // "CELLS nOffsets nConnectivity", "OFFSETS type" + nOffsets values,
  // "CONNECTIVITY type" + nConnectivity values.
  absl::Status ParseCells51(int64_t num_offsets, int64_t num_connectivity) {
    std::string_view token;
    RETURN_IF_ERROR(Need(&token, "OFFSETS", 1, 0, "data type"));  // vtktypeint64 etc.
    const int64_t offsets_line = cursor_.line();
    RETURN_IF_ERROR(ReadIntegers(num_offsets, "OFFSETS", "offsets", offsets_));
    if (num_offsets == 0) {
      return cursor_.ErrorAt(offsets_line, "OFFSETS is empty: expected number of cells + 1 values");
    }
    if (offsets_[0] != 0) {
      return cursor_.ErrorAt(offsets_line,
                             internal::Cat("OFFSETS must start at 0, found ", offsets_[0]));
    }
    for (size_t i = 1; i < offsets_.size(); ++i) {
      if (offsets_[i] < offsets_[i - 1]) {
        return cursor_.ErrorAt(offsets_line, internal::Cat("OFFSETS decrease at cell ", i - 1, ": ",
                                                           offsets_[i - 1], " then ", offsets_[i]));
      }
    }
    if (offsets_.back() != num_connectivity) {
      return cursor_.ErrorAt(offsets_line,
                             internal::Cat("the last OFFSETS value is ", offsets_.back(),
                                           ": expected the CONNECTIVITY size ", num_connectivity));
    }
    if (!cursor_.Next(&token)) {
      return cursor_.Error("unexpected end of file in CELLS: expected CONNECTIVITY");
    }
    if (!KeywordIs(token, "CONNECTIVITY")) {
      return cursor_.Error(
          internal::Cat("expected CONNECTIVITY after OFFSETS, found ", Quote(token)));
    }
    RETURN_IF_ERROR(Need(&token, "CONNECTIVITY", 1, 0, "data type"));
    const int64_t connectivity_line = cursor_.line();
    // Read the values, remembering the line where each cell starts.
    const int64_t num_cells = num_offsets - 1;
    cell_lines_.assign(static_cast<size_t>(num_cells), connectivity_line);
    connectivity_.reserve(SafeReserve(num_connectivity, cursor_.remaining_bytes(), 2));
    int64_t cell = 0;
    for (int64_t i = 0; i < num_connectivity; ++i) {
      RETURN_IF_ERROR(Need(&token, "CONNECTIVITY", num_connectivity, i, "values"));
      while (cell < num_cells && offsets_[cell] <= i) {
        if (offsets_[cell] == i) cell_lines_[cell] = cursor_.line();
        ++cell;
      }
      int64_t v;
      if (!ParseInt64(token, &v)) {
        return cursor_.Error(
            internal::Cat("bad number ", Quote(token), " in CONNECTIVITY: expected an integer"));
      }
      connectivity_.push_back(v);
    }
    return absl::OkStatus();
  }

  absl::Status ParseCellTypes() {
    if (types_line_ != 0) return cursor_.Error("second CELL_TYPES section: expected only one");
    types_line_ = cursor_.line();
    std::string_view token;
    RETURN_IF_ERROR(Need(&token, "CELL_TYPES", 1, 0, "count"));
    ASSIGN_OR_RETURN(const int64_t n, Count(token, "the number of CELL_TYPES"));
    types_.reserve(SafeReserve(n, cursor_.remaining_bytes(), 2));
    type_lines_.reserve(SafeReserve(n, cursor_.remaining_bytes(), 2));
    for (int64_t i = 0; i < n; ++i) {
      RETURN_IF_ERROR(Need(&token, "CELL_TYPES", n, i, "cell types"));
      int64_t v;
      if (!ParseInt64(token, &v)) {
        return cursor_.Error(
            internal::Cat("bad number ", Quote(token), " in CELL_TYPES: expected an integer"));
      }
      types_.push_back(v);
      type_lines_.push_back(cursor_.line());
    }
    return absl::OkStatus();
  }

  // "FIELD name numArrays", then per array "name components tuples type"
  // and components * tuples values.
  absl::Status SkipField() {
    std::string_view token;
    RETURN_IF_ERROR(Need(&token, "FIELD", 1, 0, "name"));
    RETURN_IF_ERROR(Need(&token, "FIELD", 1, 0, "array count"));
    ASSIGN_OR_RETURN(const int64_t arrays, Count(token, "the number of FIELD arrays"));
    for (int64_t a = 0; a < arrays; ++a) {
      RETURN_IF_ERROR(Need(&token, "FIELD", arrays, a, "arrays"));
      if (KeywordIs(token, "METADATA")) {
        cursor_.SkipPastBlankLine();
        --a;
        continue;
      }
      std::array<int64_t, 2> shape;
      for (int k = 0; k < 2; ++k) {
        RETURN_IF_ERROR(Need(&token, "FIELD", arrays, a, "arrays"));
        ASSIGN_OR_RETURN(shape[k], Count(token, "a FIELD array size"));
      }
      RETURN_IF_ERROR(Need(&token, "FIELD", arrays, a, "arrays"));  // data type
      const int64_t values = shape[0] * shape[1];
      for (int64_t i = 0; i < values; ++i) {
        RETURN_IF_ERROR(Need(&token, "FIELD", values, i, "array values"));
      }
    }
    return absl::OkStatus();
  }

  absl::Status PointIds(int64_t cell, std::span<const int64_t> ids, int32_t* out) {
    for (size_t i = 0; i < ids.size(); ++i) {
      if (ids[i] < 0 || ids[i] >= num_points_) {
        return cursor_.ErrorAt(
            cell_lines_[cell],
            internal::Cat("cell ", cell, " refers to point ", ids[i], ": expected 0 to ",
                          num_points_ - 1, " (POINTS has ", num_points_, ")"));
      }
      out[i] = static_cast<int32_t>(ids[i]);
    }
    return absl::OkStatus();
  }

  absl::Status AddPolyhedron(int64_t cell, std::span<const int64_t> stream, const Points& points) {
    const int64_t line = cell_lines_[cell];
    auto bad = [&](std::string_view why) {
      return cursor_.ErrorAt(line, internal::Cat("polyhedron cell ", cell, ": ", why,
                                                 " (expected nFaces, then per face nPts and "
                                                 "its point ids)"));
    };
    if (stream.empty()) return bad("empty face stream");
    const int64_t num_faces = stream[0];
    if (num_faces < 4) return bad(internal::Cat("nFaces is ", num_faces, ", at least 4 needed"));
    std::vector<std::vector<int32_t>> loops;
    loops.reserve(std::min<size_t>(static_cast<size_t>(num_faces), stream.size()));
    size_t pos = 1;
    for (int64_t f = 0; f < num_faces; ++f) {
      if (pos >= stream.size()) {
        return bad(internal::Cat("the stream ends after ", f, " of ", num_faces, " faces"));
      }
      const int64_t n = stream[pos++];
      if (n < 3) return bad(internal::Cat("face ", f, " has ", n, " points, at least 3 needed"));
      if (static_cast<size_t>(n) > stream.size() - pos) {
        return bad(internal::Cat("face ", f, " needs ", n, " point ids, the stream has ",
                                 stream.size() - pos, " left"));
      }
      std::vector<int32_t>& loop = loops.emplace_back(static_cast<size_t>(n));
      RETURN_IF_ERROR(PointIds(cell, stream.subspan(pos, static_cast<size_t>(n)), loop.data()));
      pos += static_cast<size_t>(n);
    }
    if (pos != stream.size()) {
      return bad(
          internal::Cat(stream.size() - pos, " values left over after ", num_faces, " faces"));
    }
    if (internal::SignedVolume(points, loops) < 0.0) {
      for (auto& loop : loops) std::reverse(loop.begin(), loop.end());
    }
    input_.cells.push_back(std::move(loops));
    return absl::OkStatus();
  }

  absl::StatusOr<mesh::MeshInput> BuildCells() {
    const int64_t num_cells = static_cast<int64_t>(offsets_.size()) - 1;
    if (static_cast<int64_t>(types_.size()) != num_cells) {
      return cursor_.ErrorAt(types_line_,
                             internal::Cat("CELL_TYPES has ", types_.size(),
                                           " entries: expected one per cell, ", num_cells));
    }
    input_.vertices.resize(num_points_, 3);
    std::copy(coords_.begin(), coords_.end(), input_.vertices.data());
    input_.cells.reserve(static_cast<size_t>(num_cells));
    for (int64_t c = 0; c < num_cells; ++c) {
      const int64_t type = types_[c];
      const std::span<const int64_t> ids(connectivity_.data() + offsets_[c],
                                         static_cast<size_t>(offsets_[c + 1] - offsets_[c]));
      if (type >= 0 && type <= 9) continue;  // empty, vertices, lines, polygons, quads
      if (type == kVtkPolyhedron) {
        RETURN_IF_ERROR(AddPolyhedron(c, ids, input_.vertices));
        continue;
      }
      Shape shape;
      const char* name;
      switch (type) {
        case kVtkTetra:
          shape = Shape::kTetrahedron;
          name = "VTK_TETRA";
          break;
        case kVtkVoxel:
          shape = Shape::kHexahedron;
          name = "VTK_VOXEL";
          break;
        case kVtkHexahedron:
          shape = Shape::kHexahedron;
          name = "VTK_HEXAHEDRON";
          break;
        case kVtkWedge:
          shape = Shape::kPrism;
          name = "VTK_WEDGE";
          break;
        case kVtkPyramid:
          shape = Shape::kPyramid;
          name = "VTK_PYRAMID";
          break;
        default: {
          const char* type_name = VtkTypeName(type);
          return cursor_.ErrorAt(
              type_lines_[c],
              internal::Cat("unsupported VTK cell type ", type,
                            type_name != nullptr ? internal::Cat(" (", type_name, ")") : "",
                            " for cell ", c,
                            ": supported volume types are 10 tetra, 11 voxel, 12 hexahedron, 13 "
                            "wedge, 14 pyramid, 42 polyhedron; types 0-9 are skipped"));
        }
      }
      const int needed = internal::NumNodes(shape);
      if (static_cast<int64_t>(ids.size()) != needed) {
        return cursor_.ErrorAt(cell_lines_[c], internal::Cat("cell ", c, " is a ", name, " (type ",
                                                             type, ") and needs ", needed,
                                                             " points, but lists ", ids.size()));
      }
      std::array<int32_t, 8> nodes;
      RETURN_IF_ERROR(PointIds(c, ids, nodes.data()));
      if (type == kVtkWedge) {
        const auto prism = internal::VtkWedgeToGmshPrism(nodes);
        std::copy(prism.begin(), prism.end(), nodes.begin());
      } else if (type == kVtkVoxel) {
        nodes = internal::VtkVoxelToHexahedron(nodes);
      }
      input_.cells.push_back(
          internal::CellFaces(shape, std::span<const int32_t>(nodes.data(), needed)));
    }
    if (input_.cells.empty()) {
      return cursor_.ErrorAt(types_line_,
                             "no volume cells: expected at least one tetra (10), voxel (11), "
                             "hexahedron (12), wedge (13), pyramid (14) or polyhedron (42)");
    }
    input_.origin = file_.path();
    mesh::DropUnusedVertices(input_);
    return std::move(input_);
  }

  const TextFile& file_;
  TokenCursor cursor_;
  int64_t points_line_ = 0, cells_line_ = 0, types_line_ = 0;
  int64_t num_points_ = 0;
  std::vector<double> coords_;
  std::vector<int64_t> offsets_;       // per cell start, then the end
  std::vector<int64_t> connectivity_;  // point ids (face streams for polyhedra)
  std::vector<int64_t> cell_lines_;    // line where each cell's list starts
  std::vector<int64_t> types_;
  std::vector<int64_t> type_lines_;
  mesh::MeshInput input_;
};

}  // namespace

absl::StatusOr<mesh::MeshInput> ReadVtkLegacy(const std::string& path) {
  ASSIGN_OR_RETURN(const TextFile file, TextFile::Read(path));
  VtkParser parser(file);
  return parser.Parse();
}

}  // namespace dynsolid::io
