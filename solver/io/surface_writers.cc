#include "solver/io/surface_writers.h"

#include <cstdint>
#include <string>
#include <vector>

#include "solver/common/status_macros.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace {

using internal::OutputFile;

absl::Status CheckSurface(const std::string& path, const mesh::BoundarySurface& s,
                          size_t max_face_size) {
  const int64_t nv = s.positions.rows();
  const mesh::Csr& f = s.faces;
  if (f.offsets.empty() || f.offsets.front() != 0 ||
      static_cast<size_t>(f.offsets.back()) != f.items.size()) {
    return absl::InvalidArgumentError(
        internal::Cat(path, ": surface faces are malformed: offsets must start at 0 and end at ",
                      f.items.size()));
  }
  for (int32_t r = 0; r < f.rows(); ++r) {
    const int32_t n = f.row_size(r);
    if (n < 3 || static_cast<size_t>(n) > max_face_size) {
      return absl::InvalidArgumentError(internal::Cat(path, ": surface face ", r, " has ", n,
                                                      " vertices: expected 3 to ", max_face_size));
    }
    for (int32_t v : f.row(r)) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(internal::Cat(
            path, ": surface face ", r, " refers to vertex ", v, ": expected 0 to ", nv - 1));
      }
    }
  }
  for (const mesh::VertexField& field : s.fields) {
    if (field.name.empty() || field.name.find_first_of(" \t\r\n") != std::string::npos) {
      return absl::InvalidArgumentError(internal::Cat(path, ": field name '", field.name,
                                                      "' must be non-empty and without spaces"));
    }
    if (field.components < 1 ||
        field.values.size() != static_cast<size_t>(nv) * static_cast<size_t>(field.components)) {
      return absl::InvalidArgumentError(
          internal::Cat(path, ": field '", field.name, "' has ", field.values.size(),
                        " values: expected ", nv, " vertices x ", field.components, " components"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status WriteObj(const std::string& path, const mesh::BoundarySurface& surface) {
  RETURN_IF_ERROR(CheckSurface(path, surface, SIZE_MAX));
  OutputFile out(path);
  if (!out.ok()) return out.status();
  const Points& p = surface.positions;
  out.Put("# dynsolid boundary surface: ")
      .Put(static_cast<int64_t>(p.rows()))
      .Put(" vertices, ")
      .Put(static_cast<int64_t>(surface.faces.rows()))
      .Put(" faces\n");
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    out.Put("v ").Put(p(i, 0)).Put(' ').Put(p(i, 1)).Put(' ').Put(p(i, 2)).Put('\n');
  }
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    out.Put('f');
    for (int32_t v : surface.faces.row(r)) out.Put(' ').Put(static_cast<int64_t>(v) + 1);
    out.Put('\n');
  }
  return out.Close();
}

absl::Status WritePly(const std::string& path, const mesh::BoundarySurface& surface) {
  RETURN_IF_ERROR(CheckSurface(path, surface, 255));
  OutputFile out(path);
  if (!out.ok()) return out.status();
  const Points& p = surface.positions;
  out.Put("ply\nformat ascii 1.0\ncomment dynsolid boundary surface\n");
  out.Put("element vertex ").Put(static_cast<int64_t>(p.rows())).Put('\n');
  out.Put("property double x\nproperty double y\nproperty double z\n");
  for (const mesh::VertexField& field : surface.fields) {
    for (int k = 0; k < field.components; ++k) {
      out.Put("property float ").Put(field.name);
      if (field.components == 3) {
        out.Put(k == 0 ? "_x" : k == 1 ? "_y" : "_z");
      } else if (field.components != 1) {
        out.Put('_').Put(static_cast<int64_t>(k));
      }
      out.Put('\n');
    }
  }
  out.Put("element face ").Put(static_cast<int64_t>(surface.faces.rows())).Put('\n');
  out.Put("property list uchar int vertex_indices\nend_header\n");
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    out.Put(p(i, 0)).Put(' ').Put(p(i, 1)).Put(' ').Put(p(i, 2));
    for (const mesh::VertexField& field : surface.fields) {
      for (int k = 0; k < field.components; ++k) {
        out.Put(' ').PutFloat(static_cast<float>(field.values[i * field.components + k]));
      }
    }
    out.Put('\n');
  }
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    out.Put(static_cast<int64_t>(surface.faces.row_size(r)));
    for (int32_t v : surface.faces.row(r)) out.Put(' ').Put(static_cast<int64_t>(v));
    out.Put('\n');
  }
  return out.Close();
}

}  // namespace dynsolid::io
