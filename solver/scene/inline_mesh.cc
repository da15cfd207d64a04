#include "solver/scene/inline_mesh.h"

#include <cstdint>

#include "absl/strings/str_cat.h"
#include "solver/scene/generators.h"

namespace dynsolid::scene {

absl::StatusOr<mesh::MeshInput> MeshFromInline(const InlineMesh& m) {
  constexpr const char* kField = "inline_mesh";
  if (m.vertices_size() % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        kField, ".vertices: ", m.vertices_size(), " values is not a multiple of 3 (x, y, z)"));
  }
  if (m.cell_face_counts_size() == 0) {
    return absl::InvalidArgumentError(absl::StrCat(kField, ".cell_face_counts: no cells"));
  }
  if (m.cell_face_counts_size() > kMaxGeneratedCells) {
    return absl::InvalidArgumentError(absl::StrCat(kField, ".cell_face_counts: ",
                                                   m.cell_face_counts_size(),
                                                   " cells, more than ", kMaxGeneratedCells));
  }
  int64_t faces = 0;
  for (int c = 0; c < m.cell_face_counts_size(); ++c) {
    if (m.cell_face_counts(c) < 4) {
      return absl::InvalidArgumentError(absl::StrCat(kField, ".cell_face_counts[", c, "]: ",
                                                     m.cell_face_counts(c),
                                                     " faces; a cell has at least 4"));
    }
    faces += m.cell_face_counts(c);
  }
  if (faces != m.face_sizes_size()) {
    return absl::InvalidArgumentError(absl::StrCat(kField, ".face_sizes: ", faces,
                                                   " faces listed by cell_face_counts, ",
                                                   m.face_sizes_size(), " sizes given"));
  }
  int64_t loop_total = 0;
  for (int f = 0; f < m.face_sizes_size(); ++f) {
    if (m.face_sizes(f) < 3) {
      return absl::InvalidArgumentError(absl::StrCat(kField, ".face_sizes[", f, "]: ",
                                                     m.face_sizes(f),
                                                     " vertices; a face has at least 3"));
    }
    loop_total += m.face_sizes(f);
  }
  if (loop_total != m.face_vertices_size()) {
    return absl::InvalidArgumentError(absl::StrCat(kField, ".face_vertices: ", loop_total,
                                                   " indices listed by face_sizes, ",
                                                   m.face_vertices_size(), " given"));
  }
  const int32_t nv = m.vertices_size() / 3;
  mesh::MeshInput out;
  out.origin = "inline mesh";
  out.vertices.resize(nv, 3);
  for (int32_t v = 0; v < nv; ++v) {
    for (int a = 0; a < 3; ++a) out.vertices(v, a) = m.vertices(3 * v + a);
  }
  out.cells.resize(m.cell_face_counts_size());
  int f = 0, k = 0;
  for (int c = 0; c < m.cell_face_counts_size(); ++c) {
    out.cells[c].resize(m.cell_face_counts(c));
    for (auto& loop : out.cells[c]) {
      loop.resize(m.face_sizes(f++));
      for (int32_t& v : loop) {
        v = m.face_vertices(k);
        if (v < 0 || v >= nv) {
          return absl::InvalidArgumentError(absl::StrCat(kField, ".face_vertices[", k, "]: vertex ",
                                                         v, " is out of range [0, ", nv, ")"));
        }
        ++k;
      }
    }
  }
  return out;
}

InlineMesh InlineFromMesh(const mesh::MeshInput& mesh) {
  InlineMesh m;
  m.mutable_vertices()->Reserve(static_cast<int>(3 * mesh.vertices.rows()));
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    for (int a = 0; a < 3; ++a) m.add_vertices(mesh.vertices(v, a));
  }
  for (const auto& cell : mesh.cells) {
    m.add_cell_face_counts(static_cast<int32_t>(cell.size()));
    for (const auto& loop : cell) {
      m.add_face_sizes(static_cast<int32_t>(loop.size()));
      for (int32_t v : loop) m.add_face_vertices(v);
    }
  }
  return m;
}

}  // namespace dynsolid::scene
