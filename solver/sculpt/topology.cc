// Shared checks and the final validation of every topology edit, and SetSharp.
#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/sculpt/edit_common.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::sculpt {
namespace internal {
namespace {

std::string PointString(const Points& p, int32_t v) {
  return absl::StrCat("(", p(v, 0), ", ", p(v, 1), ", ", p(v, 2), ")");
}

// New cells (cell_source -1) must also have positive volume in the current
// configuration: new material is added where the deformed solid is, and an
// inverted element there would break the next step. (Old and refined cells
// are the simulation's business.) Same tolerance as CellComplex::FromInput.
absl::Status CheckNewCellsCurrent(const mesh::CellComplex& built, const EditResult& result) {
  mesh::CellComplex deformed = built;
  deformed.set_positions(result.current);
  for (int32_t c = 0; c < deformed.num_cells(); ++c) {
    if (result.cell_source[c] >= 0) continue;
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
    for (int32_t v : deformed.cell_vertices(c)) {
      lo = lo.cwiseMin(result.current.row(v).transpose());
      hi = hi.cwiseMax(result.current.row(v).transpose());
    }
    const double size = (hi - lo).maxCoeff();
    const double vol = deformed.CellVolume(c);
    if (!(vol > 1e-12 * size * size * size)) {
      return absl::InvalidArgumentError(
          absl::StrCat("new cell ", c, " has ", vol < 0.0 ? "negative" : "zero", " volume ", vol,
                       " in the current (deformed) configuration (size ", size,
                       "); the faces do not face each other there"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckState(const mesh::CellComplex& rest, const Points& current,
                        const std::vector<uint8_t>& sharp) {
  if (current.rows() != rest.num_vertices()) {
    return absl::InvalidArgumentError(absl::StrCat("current: ", current.rows(),
                                                   " positions for a control mesh of ",
                                                   rest.num_vertices(), " vertices"));
  }
  for (int32_t v = 0; v < current.rows(); ++v) {
    if (!current.row(v).allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("current[", v, "]: vertex ", v, " has a non-finite coordinate"));
    }
  }
  if (!sharp.empty() && static_cast<int32_t>(sharp.size()) != rest.num_edges()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "sharp: ", sharp.size(), " tags for a control mesh of ", rest.num_edges(), " edges"));
  }
  return absl::OkStatus();
}

absl::Status CheckIds(std::span<const int32_t> ids, int32_t count, absl::string_view field,
                      absl::string_view item) {
  if (ids.empty()) return absl::InvalidArgumentError(absl::StrCat(field, ": no ", item, " given"));
  std::vector<int32_t> first(count, -1);  // first position of each id
  for (size_t i = 0; i < ids.size(); ++i) {
    const int32_t id = ids[i];
    if (id < 0 || id >= count) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, "[", i, "]: ", item, " ", id, " is out of range [0, ", count, ")"));
    }
    if (first[id] >= 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, "[", i, "]: ", item, " ", id, " is repeated (also ", field, "[", first[id], "])"));
    }
    first[id] = static_cast<int32_t>(i);
  }
  return absl::OkStatus();
}

mesh::MeshInput ToInput(const mesh::CellComplex& complex) {
  mesh::MeshInput input;
  input.vertices = complex.positions();
  input.cells.resize(complex.num_cells());
  for (int32_t c = 0; c < complex.num_cells(); ++c) {
    const int32_t nf = static_cast<int32_t>(complex.cell_faces(c).size());
    input.cells[c].resize(nf);
    for (int32_t k = 0; k < nf; ++k) complex.CellFaceLoop(c, k, input.cells[c][k]);
  }
  return input;
}

std::vector<std::array<int32_t, 2>> SharpPairs(const mesh::CellComplex& rest,
                                               const std::vector<uint8_t>& sharp) {
  std::vector<std::array<int32_t, 2>> pairs;
  for (size_t e = 0; e < sharp.size(); ++e) {
    if (sharp[e]) pairs.push_back(rest.edge_vertices(static_cast<int32_t>(e)));
  }
  return pairs;
}

std::vector<std::vector<std::pair<int32_t, double>>> IdentitySources(int32_t n) {
  std::vector<std::vector<std::pair<int32_t, double>>> rows(n);
  for (int32_t v = 0; v < n; ++v) rows[v] = {{v, 1.0}};
  return rows;
}

absl::Status CheckManifold(const mesh::CellComplex& complex) {
  const Points& p = complex.positions();
  for (int32_t e = 0; e < complex.num_edges(); ++e) {
    if (!complex.edge_is_boundary(e)) continue;
    int32_t n = 0;
    for (int32_t f : complex.edge_faces(e)) n += complex.face_is_boundary(f) ? 1 : 0;
    if (n != 2) {
      const auto& ev = complex.edge_vertices(e);
      return absl::InvalidArgumentError(absl::StrCat(
          "non-manifold result: edge (", ev[0], " ", ev[1], ") from ", PointString(p, ev[0]),
          " to ", PointString(p, ev[1]), " lies in ", n,
          " boundary faces (parts of the solid touch along it); a boundary edge needs 2"));
    }
  }
  // Around a boundary vertex, join boundary faces that share a boundary edge
  // at the vertex; they must form one fan.
  std::vector<int32_t> faces, parent;
  for (int32_t v = 0; v < complex.num_vertices(); ++v) {
    if (!complex.vertex_is_boundary(v)) continue;
    faces.clear();
    for (int32_t f : complex.vertex_faces(v)) {
      if (complex.face_is_boundary(f)) faces.push_back(f);
    }
    parent.resize(faces.size());
    for (size_t i = 0; i < faces.size(); ++i) parent[i] = static_cast<int32_t>(i);
    auto find = [&](int32_t i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    for (int32_t e : complex.vertex_edges(v)) {
      if (!complex.edge_is_boundary(e)) continue;
      int32_t first = -1;
      for (int32_t f : complex.edge_faces(e)) {
        if (!complex.face_is_boundary(f)) continue;
        const int32_t i =
            static_cast<int32_t>(std::find(faces.begin(), faces.end(), f) - faces.begin());
        if (first < 0) {
          first = i;
        } else {
          parent[find(i)] = find(first);
        }
      }
    }
    int32_t fans = 0;
    for (size_t i = 0; i < faces.size(); ++i)
      fans += find(static_cast<int32_t>(i)) == static_cast<int32_t>(i) ? 1 : 0;
    if (fans != 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("non-manifold result: vertex ", v, " at ", PointString(p, v),
                       " joins parts of the solid that touch only there (its boundary faces form ",
                       fans, " fans; a boundary vertex needs 1)"));
    }
  }
  return absl::OkStatus();
}

std::vector<int32_t> CellComponents(const mesh::CellComplex& complex, int32_t* count) {
  std::vector<int32_t> comp(complex.num_cells(), -1);
  std::vector<int32_t> stack;
  int32_t n = 0;
  for (int32_t c0 = 0; c0 < complex.num_cells(); ++c0) {
    if (comp[c0] >= 0) continue;
    comp[c0] = n;
    stack.assign(1, c0);
    while (!stack.empty()) {
      const int32_t c = stack.back();
      stack.pop_back();
      for (int32_t f : complex.cell_faces(c)) {
        for (int32_t d : complex.face_cells(f)) {
          if (d >= 0 && comp[d] < 0) {
            comp[d] = n;
            stack.push_back(d);
          }
        }
      }
    }
    ++n;
  }
  if (count != nullptr) *count = n;
  return comp;
}

Eigen::Vector3d LoopNormal(const Points& positions, std::span<const int32_t> loop) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  const size_t k = loop.size();
  for (size_t i = 0; i < k; ++i) {
    const Eigen::Vector3d a = positions.row(loop[i]).transpose();
    const Eigen::Vector3d b = positions.row(loop[(i + 1) % k]).transpose();
    n += a.cross(b);
  }
  const double len = n.norm();
  if (!(len > 0.0) || !std::isfinite(len)) return Eigen::Vector3d::Zero();
  return n / len;
}

std::string Count(int64_t n, absl::string_view noun) {
  if (n == 1) return absl::StrCat(n, " ", noun);
  if (noun == "vertex") return absl::StrCat(n, " vertices");
  return absl::StrCat(n, " ", noun, "s");
}

absl::StatusOr<EditResult> Finish(absl::string_view edit, EditResult result,
                                  const std::vector<std::array<int32_t, 2>>& sharp_pairs) {
  const auto fail = [&](const absl::Status& s) {
    return absl::Status(s.code(), absl::StrCat(edit, ": ", s.message()));
  };
  absl::StatusOr<mesh::CellComplex> built = mesh::CellComplex::FromInput(result.mesh);
  if (!built.ok()) return fail(built.status());
  if (absl::Status s = CheckManifold(*built); !s.ok()) return fail(s);
  if (absl::Status s = CheckNewCellsCurrent(*built, result); !s.ok()) return fail(s);
  std::vector<uint8_t> tags(built->num_edges(), 0);
  for (const auto& [a, b] : sharp_pairs) {
    const int32_t e = built->FindEdge(a, b);
    if (e >= 0) tags[e] = 1;
  }
  result.sharp_edges = SharpPairs(*built, tags);
  result.complex = std::make_shared<mesh::CellComplex>(*std::move(built));
  return result;
}

}  // namespace internal

absl::StatusOr<EditResult> SetSharp(const mesh::CellComplex& rest, const Points& current,
                                    const std::vector<uint8_t>& sharp,
                                    std::span<const std::array<int32_t, 2>> edges, bool on) {
  RETURN_IF_ERROR(internal::CheckState(rest, current, sharp));
  if (edges.empty()) return absl::InvalidArgumentError("edges: no edge given");
  std::vector<uint8_t> tags = sharp;
  tags.resize(rest.num_edges(), 0);
  const int32_t nv = rest.num_vertices();
  for (size_t i = 0; i < edges.size(); ++i) {
    const auto& [a, b] = edges[i];
    if (a < 0 || a >= nv || b < 0 || b >= nv) {
      return absl::InvalidArgumentError(
          absl::StrCat("edges[", i, "]: (", a, " ", b, "): vertex id out of range [0, ", nv, ")"));
    }
    const int32_t e = rest.FindEdge(a, b);
    if (e < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("edges[", i, "]: (", a, " ", b, ") is not an edge of the control mesh"));
    }
    tags[e] = on ? 1 : 0;
  }
  EditResult result;
  result.mesh = internal::ToInput(rest);
  result.current = current;
  result.vertex_sources = internal::IdentitySources(nv);
  result.cell_source.resize(rest.num_cells());
  for (int32_t c = 0; c < rest.num_cells(); ++c) result.cell_source[c] = c;
  result.summary = absl::StrCat(on ? "tagged " : "untagged ", internal::Count(edges.size(), "edge"),
                                on ? " sharp" : " (smooth)");
  return internal::Finish("set sharp", std::move(result), internal::SharpPairs(rest, tags));
}

}  // namespace dynsolid::sculpt
