// Gmsh .msh ASCII reader (formats 2.x and 4.1). Line-based: Gmsh writes one
// record per line, and holding to that lets every message name the line.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "solver/common/status_macros.h"
#include "solver/io/cell_shapes.h"
#include "solver/io/mesh_readers.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace {

using internal::LineCursor;
using internal::ParseDouble;
using internal::ParseInt64;
using internal::Quote;
using internal::SafeReserve;
using internal::Shape;
using internal::TextFile;

constexpr int64_t kMaxCount = std::numeric_limits<int32_t>::max();

// What the reader does with a Gmsh element type.
struct GmshType {
  int type;
  int nodes;
  const char* name;
  enum Use : uint8_t { kCell, kSkip, kReject } use;
  Shape shape;  // for kCell
};

// Gmsh's element types 1-19 (gmsh.info/doc, "MSH file format"); the
// rejected ones are listed only to name them in messages.
constexpr GmshType kGmshTypes[] = {
    {1, 2, "2-node line", GmshType::kSkip, Shape::kTetrahedron},
    {2, 3, "3-node triangle", GmshType::kSkip, Shape::kTetrahedron},
    {3, 4, "4-node quadrangle", GmshType::kSkip, Shape::kTetrahedron},
    {4, 4, "4-node tetrahedron", GmshType::kCell, Shape::kTetrahedron},
    {5, 8, "8-node hexahedron", GmshType::kCell, Shape::kHexahedron},
    {6, 6, "6-node prism", GmshType::kCell, Shape::kPrism},
    {7, 5, "5-node pyramid", GmshType::kCell, Shape::kPyramid},
    {8, 3, "3-node second-order line", GmshType::kReject, Shape::kTetrahedron},
    {9, 6, "6-node second-order triangle", GmshType::kReject, Shape::kTetrahedron},
    {10, 9, "9-node second-order quadrangle", GmshType::kReject, Shape::kTetrahedron},
    {11, 10, "10-node second-order tetrahedron", GmshType::kReject, Shape::kTetrahedron},
    {12, 27, "27-node second-order hexahedron", GmshType::kReject, Shape::kTetrahedron},
    {13, 18, "18-node second-order prism", GmshType::kReject, Shape::kTetrahedron},
    {14, 14, "14-node second-order pyramid", GmshType::kReject, Shape::kTetrahedron},
    {15, 1, "1-node point", GmshType::kSkip, Shape::kTetrahedron},
    {16, 8, "8-node second-order quadrangle", GmshType::kReject, Shape::kTetrahedron},
    {17, 20, "20-node second-order hexahedron", GmshType::kReject, Shape::kTetrahedron},
    {18, 15, "15-node second-order prism", GmshType::kReject, Shape::kTetrahedron},
    {19, 13, "13-node second-order pyramid", GmshType::kReject, Shape::kTetrahedron},
};

const GmshType* FindGmshType(int64_t type) {
  for (const GmshType& t : kGmshTypes) {
    if (t.type == type) return &t;
  }
  return nullptr;
}

std::string UnsupportedTypeMessage(int64_t type) {
  const GmshType* t = FindGmshType(type);
  return internal::Cat(
      "unsupported Gmsh element type ", type, t != nullptr ? internal::Cat(" (", t->name, ")") : "",
      ": only linear volume elements are read (4 tetrahedron, 5 hexahedron, 6 prism, "
      "7 pyramid); types 15 (point), 1 (line), 2 (triangle), 3 (quadrangle) are skipped");
}

// Node tag -> vertex index. Dense table when the tags are compact (the
// usual case), sorted pairs with binary search when they are very sparse.
class TagMap {
 public:
  // `tags[i]` is vertex i's tag, defined at `lines[i]`. Rejects duplicates.
  absl::Status Build(const std::vector<int64_t>& tags, const std::vector<int64_t>& lines,
                     const TextFile& file) {
    int64_t max_tag = 0;
    for (int64_t t : tags) max_tag = std::max(max_tag, t);
    const int64_t n = static_cast<int64_t>(tags.size());
    dense_ = max_tag <= 4 * n + (1 << 20);
    if (dense_) {
      table_.assign(static_cast<size_t>(max_tag) + 1, -1);
      for (int64_t i = 0; i < n; ++i) {
        int32_t& slot = table_[static_cast<size_t>(tags[i])];
        if (slot >= 0) return Duplicate(tags[i], lines[slot], lines[i], file);
        slot = static_cast<int32_t>(i);
      }
    } else {
      pairs_.resize(tags.size());
      for (int64_t i = 0; i < n; ++i) pairs_[i] = {tags[i], static_cast<int32_t>(i)};
      std::sort(pairs_.begin(), pairs_.end());
      for (size_t i = 1; i < pairs_.size(); ++i) {
        if (pairs_[i].first == pairs_[i - 1].first) {
          return Duplicate(pairs_[i].first, lines[pairs_[i - 1].second], lines[pairs_[i].second],
                           file);
        }
      }
    }
    return absl::OkStatus();
  }

  // Vertex index of `tag`, or -1.
  int32_t Find(int64_t tag) const {
    if (tag < 0) return -1;
    if (dense_) return tag < static_cast<int64_t>(table_.size()) ? table_[tag] : -1;
    const auto it =
        std::lower_bound(pairs_.begin(), pairs_.end(), std::pair<int64_t, int32_t>{tag, -1});
    return it != pairs_.end() && it->first == tag ? it->second : -1;
  }

 private:
  static absl::Status Duplicate(int64_t tag, int64_t first_line, int64_t line,
                                const TextFile& file) {
    return file.Error(line, internal::Cat("node tag ", tag, " is defined twice (first at line ",
                                          first_line, ")"));
  }

  bool dense_ = true;
  std::vector<int32_t> table_;
  std::vector<std::pair<int64_t, int32_t>> pairs_;
};

class GmshParser {
 public:
  explicit GmshParser(const TextFile& file) : file_(file), cursor_(file) {}

  absl::StatusOr<mesh::MeshInput> Parse() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return file_.Error(1, "empty file: expected a Gmsh mesh starting with $MeshFormat");
    }
    if (internal::Trim(line) != "$MeshFormat") {
      return cursor_.Error(internal::Cat("expected $MeshFormat (a Gmsh .msh file), found ",
                                         Quote(internal::Trim(line))));
    }
    RETURN_IF_ERROR(ParseFormat());
    while (cursor_.NextNonBlank(&line)) {
      const std::string_view header = internal::Trim(line);
      if (header == "$Nodes") {
        if (have_nodes_) return cursor_.Error("second $Nodes section: expected only one");
        RETURN_IF_ERROR(version_ == 2 ? ParseNodes2() : ParseNodes41());
        have_nodes_ = true;
      } else if (header == "$Elements") {
        if (!have_nodes_) {
          return cursor_.Error("$Elements before $Nodes: expected $Nodes first");
        }
        if (have_elements_) return cursor_.Error("second $Elements section: expected only one");
        RETURN_IF_ERROR(version_ == 2 ? ParseElements2() : ParseElements41());
        have_elements_ = true;
      } else if (header == "$MeshFormat") {
        return cursor_.Error("second $MeshFormat section");
      } else if (header.size() > 1 && header.front() == '$' && header.substr(0, 4) != "$End") {
        RETURN_IF_ERROR(SkipSection(header));
      } else {
        return cursor_.Error(internal::Cat(
            "expected a section header such as $Nodes or $Elements, found ", Quote(header)));
      }
    }
    if (!have_nodes_) return cursor_.Error("no $Nodes section: expected $Nodes and $Elements");
    if (!have_elements_) return cursor_.Error("no $Elements section: expected $Elements");
    if (input_.cells.empty()) {
      return cursor_.Error(
          "no volume elements: expected at least one tetrahedron (4), hexahedron (5), prism (6) "
          "or pyramid (7) in $Elements");
    }
    input_.vertices.resize(static_cast<Eigen::Index>(coords_.size() / 3), 3);
    std::copy(coords_.begin(), coords_.end(), input_.vertices.data());
    input_.origin = file_.path();
    mesh::DropUnusedVertices(input_);
    return std::move(input_);
  }

 private:
  absl::Status ParseFormat() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error(
          "unexpected end of file in $MeshFormat: expected 'version file-type data-size'");
    }
    internal::SplitFields(line, fields_);
    if (fields_.size() < 3) {
      return cursor_.Error(
          internal::Cat("expected 'version file-type data-size' in $MeshFormat, found ",
                        Quote(internal::Trim(line))));
    }
    const std::string_view v = fields_[0];
    if (v == "2" || v == "2.0" || v == "2.1" || v == "2.2") {
      version_ = 2;
    } else if (v == "4.1") {
      version_ = 41;
    } else {
      return cursor_.Error(internal::Cat("unsupported Gmsh format version ", Quote(v),
                                         ": expected 2.2 or 4.1 (gmsh -format msh22 or msh41)"));
    }
    if (fields_[1] == "1") {
      return cursor_.Error(
          "binary Gmsh file: only ASCII .msh files are read; convert with "
          "'gmsh in.msh -save -format msh41 -o out.msh' (ASCII unless -bin is given)");
    }
    if (fields_[1] != "0") {
      return cursor_.Error(internal::Cat("bad file-type ", Quote(fields_[1]),
                                         " in $MeshFormat: expected 0 (ASCII)"));
    }
    if (!cursor_.NextNonBlank(&line) || internal::Trim(line) != "$EndMeshFormat") {
      return cursor_.Error("expected $EndMeshFormat after the format line");
    }
    return absl::OkStatus();
  }

  // Skips an unknown section "$Name" up to "$EndName".
  absl::Status SkipSection(std::string_view header) {
    const std::string end = internal::Cat("$End", header.substr(1));
    const int64_t start = cursor_.line();
    std::string_view line;
    while (cursor_.Next(&line)) {
      if (internal::Trim(line) == end) return absl::OkStatus();
    }
    return cursor_.Error(internal::Cat("unexpected end of file in ", header, " (opened at line ",
                                       start, "): expected ", end));
  }

  // Reads the next record line of `section` into fields_. `expected`/`got`
  // and `noun` describe the progress for the error messages.
  absl::Status NextRecord(std::string_view section, int64_t expected, int64_t got,
                          std::string_view noun) {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error(internal::Cat("unexpected end of file in ", section, ": expected ",
                                         expected, " ", noun, ", got ", got));
    }
    const std::string_view t = internal::Trim(line);
    if (t.front() == '$') {
      return cursor_.Error(internal::Cat(section, " ended early at ", Quote(t), ": expected ",
                                         expected, " ", noun, ", got ", got));
    }
    internal::SplitFields(line, fields_);
    return absl::OkStatus();
  }

  absl::Status ExpectEnd(std::string_view end, std::string_view section, int64_t count,
                         std::string_view noun) {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error(
          internal::Cat("unexpected end of file in ", section, ": expected ", end));
    }
    if (internal::Trim(line) != end) {
      return cursor_.Error(internal::Cat("expected ", end, " after ", count, " ", noun,
                                         " (as declared), found ", Quote(internal::Trim(line))));
    }
    return absl::OkStatus();
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

  absl::StatusOr<int64_t> Integer(std::string_view token, std::string_view what) {
    int64_t v;
    if (!ParseInt64(token, &v)) {
      return cursor_.Error(
          internal::Cat("bad number ", Quote(token), " for ", what, ": expected an integer"));
    }
    return v;
  }

  absl::StatusOr<int64_t> Tag(std::string_view token, std::string_view what) {
    int64_t v;
    if (!ParseInt64(token, &v) || v <= 0) {
      return cursor_.Error(internal::Cat("bad number ", Quote(token), " for ", what,
                                         ": expected a positive integer"));
    }
    return v;
  }

  // x y z from fields_[first..first+2] for the node with `tag`.
  absl::Status AddCoordinates(size_t first, int64_t tag) {
    static constexpr const char* kAxis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      const std::string_view token = fields_[first + k];
      double v;
      if (!ParseDouble(token, &v)) {
        return cursor_.Error(internal::Cat("bad number ", Quote(token), " for the ", kAxis[k],
                                           " coordinate of node ", tag, ": expected a number"));
      }
      if (!std::isfinite(v)) {
        return cursor_.Error(internal::Cat("coordinate ", Quote(token), " (", kAxis[k],
                                           ") of node ", tag, " is not finite"));
      }
      coords_.push_back(v);
    }
    return absl::OkStatus();
  }

  absl::Status BuildTagMap() { return tag_map_.Build(node_tags_, node_lines_, file_); }

  // Version 2: count, then "tag x y z" per line.
  absl::Status ParseNodes2() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error("unexpected end of file in $Nodes: expected the number of nodes");
    }
    internal::SplitFields(line, fields_);
    if (fields_.size() != 1) {
      return cursor_.Error(internal::Cat("expected the number of nodes after $Nodes, found ",
                                         Quote(internal::Trim(line))));
    }
    ASSIGN_OR_RETURN(const int64_t n, Count(fields_[0], "the number of nodes"));
    Reserve(n);
    for (int64_t i = 0; i < n; ++i) {
      RETURN_IF_ERROR(NextRecord("$Nodes", n, i, "nodes"));
      if (fields_.size() != 4) {
        return cursor_.Error(internal::Cat("expected 'node-tag x y z' (4 numbers), found ",
                                           fields_.size(), " fields"));
      }
      ASSIGN_OR_RETURN(const int64_t tag, Tag(fields_[0], "a node tag"));
      RETURN_IF_ERROR(AddCoordinates(1, tag));
      node_tags_.push_back(tag);
      node_lines_.push_back(cursor_.line());
    }
    RETURN_IF_ERROR(ExpectEnd("$EndNodes", "$Nodes", n, "nodes"));
    return BuildTagMap();
  }

  // Version 4.1: "numEntityBlocks numNodes minTag maxTag", then per block
  // "entityDim entityTag parametric numNodesInBlock", its tags (one per
  // line), then its coordinates "x y z [u [v [w]]]" (one node per line).
  absl::Status ParseNodes41() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error(
          "unexpected end of file in $Nodes: expected 'numEntityBlocks numNodes minNodeTag "
          "maxNodeTag'");
    }
    internal::SplitFields(line, fields_);
    if (fields_.size() != 4) {
      return cursor_.Error(internal::Cat(
          "expected 'numEntityBlocks numNodes minNodeTag maxNodeTag' after $Nodes, found ",
          Quote(internal::Trim(line))));
    }
    ASSIGN_OR_RETURN(const int64_t blocks, Count(fields_[0], "numEntityBlocks"));
    ASSIGN_OR_RETURN(const int64_t n, Count(fields_[1], "numNodes"));
    Reserve(n);
    int64_t got = 0;
    for (int64_t b = 0; b < blocks; ++b) {
      RETURN_IF_ERROR(NextRecord("$Nodes", blocks, b, "entity blocks"));
      if (fields_.size() != 4) {
        return cursor_.Error(internal::Cat(
            "expected a node block header 'entityDim entityTag parametric numNodesInBlock', "
            "found ",
            fields_.size(), " fields"));
      }
      ASSIGN_OR_RETURN(const int64_t dim, Integer(fields_[0], "entityDim"));
      ASSIGN_OR_RETURN(const int64_t parametric, Integer(fields_[2], "parametric"));
      ASSIGN_OR_RETURN(const int64_t in_block, Count(fields_[3], "numNodesInBlock"));
      if (dim < 0 || dim > 3) {
        return cursor_.Error(internal::Cat("bad entityDim ", dim, ": expected 0, 1, 2 or 3"));
      }
      if (parametric != 0 && parametric != 1) {
        return cursor_.Error(
            internal::Cat("bad parametric flag ", parametric, ": expected 0 or 1"));
      }
      if (got + in_block > n) {
        return cursor_.Error(
            internal::Cat("node blocks hold more than the ", n, " nodes declared after $Nodes"));
      }
      const size_t first = node_tags_.size();
      for (int64_t i = 0; i < in_block; ++i) {
        RETURN_IF_ERROR(NextRecord("$Nodes", n, got, "nodes"));
        if (fields_.size() != 1) {
          return cursor_.Error(internal::Cat("expected one node tag per line in block ", b + 1,
                                             ", found ", fields_.size(), " fields"));
        }
        ASSIGN_OR_RETURN(const int64_t tag, Tag(fields_[0], "a node tag"));
        node_tags_.push_back(tag);
        node_lines_.push_back(cursor_.line());
      }
      const size_t expected_fields = 3 + (parametric == 1 ? static_cast<size_t>(dim) : 0);
      for (int64_t i = 0; i < in_block; ++i) {
        RETURN_IF_ERROR(NextRecord("$Nodes", n, got, "nodes"));
        const int64_t tag = node_tags_[first + i];
        if (fields_.size() != expected_fields) {
          return cursor_.Error(internal::Cat("expected ", expected_fields, " coordinates for node ",
                                             tag, ", found ", fields_.size(), " fields"));
        }
        RETURN_IF_ERROR(AddCoordinates(0, tag));
        ++got;
      }
    }
    if (got != n) {
      return cursor_.Error(internal::Cat("node blocks hold ", got, " nodes, but ", n,
                                         " were declared after $Nodes"));
    }
    RETURN_IF_ERROR(ExpectEnd("$EndNodes", "$Nodes", n, "nodes"));
    return BuildTagMap();
  }

  // Adds one element of type `t` whose node tags are `tags`.
  absl::Status AddElement(const GmshType& t, std::span<const std::string_view> tags,
                          int64_t element_tag) {
    int32_t nodes[8];
    for (int i = 0; i < t.nodes; ++i) {
      int64_t tag;
      if (!ParseInt64(tags[i], &tag)) {
        return cursor_.Error(internal::Cat("bad number ", Quote(tags[i]), " for node ", i + 1,
                                           " of element ", element_tag, ": expected an integer"));
      }
      if (t.use != GmshType::kCell) continue;
      const int32_t v = tag_map_.Find(tag);
      if (v < 0) {
        return cursor_.Error(internal::Cat("element ", element_tag, ": node tag ", tag,
                                           " is not defined in $Nodes"));
      }
      nodes[i] = v;
    }
    if (t.use == GmshType::kCell) {
      input_.cells.push_back(internal::CellFaces(t.shape, {nodes, static_cast<size_t>(t.nodes)}));
    }
    return absl::OkStatus();
  }

  absl::StatusOr<const GmshType*> Type(int64_t type) {
    const GmshType* t = FindGmshType(type);
    if (t == nullptr || t->use == GmshType::kReject) {
      return cursor_.Error(UnsupportedTypeMessage(type));
    }
    return t;
  }

  // Version 2: count, then "elm-number elm-type number-of-tags <tags>
  // node-tags..." per line.
  absl::Status ParseElements2() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error("unexpected end of file in $Elements: expected the number of elements");
    }
    internal::SplitFields(line, fields_);
    if (fields_.size() != 1) {
      return cursor_.Error(internal::Cat("expected the number of elements after $Elements, found ",
                                         Quote(internal::Trim(line))));
    }
    ASSIGN_OR_RETURN(const int64_t n, Count(fields_[0], "the number of elements"));
    input_.cells.reserve(SafeReserve(n, cursor_.remaining_bytes(), 16));
    for (int64_t i = 0; i < n; ++i) {
      RETURN_IF_ERROR(NextRecord("$Elements", n, i, "elements"));
      if (fields_.size() < 3) {
        return cursor_.Error(
            internal::Cat("expected 'elm-number elm-type number-of-tags tags... nodes...', found ",
                          fields_.size(), " fields"));
      }
      ASSIGN_OR_RETURN(const int64_t number, Integer(fields_[0], "the element number"));
      ASSIGN_OR_RETURN(const int64_t type, Integer(fields_[1], "the element type"));
      ASSIGN_OR_RETURN(const int64_t ntags, Count(fields_[2], "the number of tags"));
      ASSIGN_OR_RETURN(const GmshType* t, Type(type));
      const size_t expected = 3 + static_cast<size_t>(ntags) + static_cast<size_t>(t->nodes);
      if (fields_.size() != expected) {
        return cursor_.Error(internal::Cat("element ", number, " (", t->name, ") with ", ntags,
                                           " tags has ", fields_.size(), " fields: expected ",
                                           expected, " (", t->nodes, " node tags)"));
      }
      RETURN_IF_ERROR(
          AddElement(*t, std::span<const std::string_view>(fields_).subspan(3 + ntags), number));
    }
    return ExpectEnd("$EndElements", "$Elements", n, "elements");
  }

  // Version 4.1: "numEntityBlocks numElements minTag maxTag", then per block
  // "entityDim entityTag elementType numElementsInBlock" and one line
  // "elementTag node-tags..." per element.
  absl::Status ParseElements41() {
    std::string_view line;
    if (!cursor_.NextNonBlank(&line)) {
      return cursor_.Error(
          "unexpected end of file in $Elements: expected 'numEntityBlocks numElements "
          "minElementTag maxElementTag'");
    }
    internal::SplitFields(line, fields_);
    if (fields_.size() != 4) {
      return cursor_.Error(
          internal::Cat("expected 'numEntityBlocks numElements minElementTag maxElementTag' after "
                        "$Elements, found ",
                        Quote(internal::Trim(line))));
    }
    ASSIGN_OR_RETURN(const int64_t blocks, Count(fields_[0], "numEntityBlocks"));
    ASSIGN_OR_RETURN(const int64_t n, Count(fields_[1], "numElements"));
    input_.cells.reserve(SafeReserve(n, cursor_.remaining_bytes(), 16));
    int64_t got = 0;
    for (int64_t b = 0; b < blocks; ++b) {
      RETURN_IF_ERROR(NextRecord("$Elements", blocks, b, "entity blocks"));
      if (fields_.size() != 4) {
        return cursor_.Error(
            internal::Cat("expected an element block header 'entityDim entityTag elementType "
                          "numElementsInBlock', found ",
                          fields_.size(), " fields"));
      }
      ASSIGN_OR_RETURN(const int64_t type, Integer(fields_[2], "elementType"));
      ASSIGN_OR_RETURN(const int64_t in_block, Count(fields_[3], "numElementsInBlock"));
      ASSIGN_OR_RETURN(const GmshType* t, Type(type));
      if (got + in_block > n) {
        return cursor_.Error(internal::Cat("element blocks hold more than the ", n,
                                           " elements declared after $Elements"));
      }
      for (int64_t i = 0; i < in_block; ++i) {
        RETURN_IF_ERROR(NextRecord("$Elements", n, got, "elements"));
        ASSIGN_OR_RETURN(const int64_t number, Integer(fields_[0], "the element tag"));
        if (fields_.size() != static_cast<size_t>(1 + t->nodes)) {
          return cursor_.Error(internal::Cat("element ", number, " (", t->name, ") has ",
                                             fields_.size() - 1, " node tags: expected ",
                                             t->nodes));
        }
        RETURN_IF_ERROR(
            AddElement(*t, std::span<const std::string_view>(fields_).subspan(1), number));
        ++got;
      }
    }
    if (got != n) {
      return cursor_.Error(internal::Cat("element blocks hold ", got, " elements, but ", n,
                                         " were declared after $Elements"));
    }
    return ExpectEnd("$EndElements", "$Elements", n, "elements");
  }

  void Reserve(int64_t n) {
    // A node line has at least 8 bytes ("1 0 0 0\n").
    const size_t r = SafeReserve(n, cursor_.remaining_bytes(), 8);
    coords_.reserve(3 * r);
    node_tags_.reserve(r);
    node_lines_.reserve(r);
  }

  const TextFile& file_;
  LineCursor cursor_;
  std::vector<std::string_view> fields_;
  int version_ = 0;  // 2 or 41
  bool have_nodes_ = false;
  bool have_elements_ = false;
  std::vector<double> coords_;
  std::vector<int64_t> node_tags_;
  std::vector<int64_t> node_lines_;
  TagMap tag_map_;
  mesh::MeshInput input_;
};

}  // namespace

absl::StatusOr<mesh::MeshInput> ReadGmsh(const std::string& path) {
  ASSIGN_OR_RETURN(const TextFile file, TextFile::Read(path));
  GmshParser parser(file);
  return parser.Parse();
}

}  // namespace dynsolid::io
