#include "solver/io/surface_writers.h"

#include <Eigen/Geometry>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "solver/common/status_macros.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace internal {

absl::Status CheckSurface(const mesh::BoundarySurface& s, const SurfaceRules& rules) {
  const int64_t nv = s.positions.rows();
  const mesh::Csr& f = s.faces;
  if (f.offsets.empty() || f.offsets.front() != 0 ||
      static_cast<size_t>(f.offsets.back()) != f.items.size()) {
    return absl::InvalidArgumentError(
        Cat("surface faces are malformed: offsets must start at 0 and end at ", f.items.size()));
  }
  for (int32_t r = 0; r < f.rows(); ++r) {
    const int32_t n = f.row_size(r);
    if (n < 3 || static_cast<size_t>(n) > rules.max_face_size) {
      return absl::InvalidArgumentError(
          Cat("surface face ", r, " has ", n, " vertices: expected 3 to ", rules.max_face_size));
    }
    for (int32_t v : f.row(r)) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(
            Cat("surface face ", r, " refers to vertex ", v, ": expected 0 to ", nv - 1));
      }
    }
  }
  if (rules.need_faces && f.rows() == 0) {
    return absl::InvalidArgumentError(
        Cat("surface has no faces (", nv, " vertices): nothing to triangulate"));
  }
  if (rules.finite_positions || rules.float32_positions) {
    constexpr double kFloatMax = std::numeric_limits<float>::max();
    for (int64_t i = 0; i < nv; ++i) {
      for (int k = 0; k < 3; ++k) {
        const double x = s.positions(i, k);
        const char axis = static_cast<char>('x' + k);
        if (!std::isfinite(x)) {
          return absl::InvalidArgumentError(Cat("surface vertex ", i,
                                                " has a non-finite coordinate ", axis, " (",
                                                std::isnan(x) ? "nan"
                                                : x > 0       ? "inf"
                                                              : "-inf",
                                                ")"));
        }
        if (rules.float32_positions && std::abs(x) > kFloatMax) {
          return absl::InvalidArgumentError(Cat("surface vertex ", i, " has coordinate ", axis,
                                                " = ", x, ", beyond float32's range"));
        }
      }
    }
  }
  for (const mesh::VertexField& field : s.fields) {
    if (field.name.empty() || field.name.find_first_of(" \t\r\n") != std::string::npos) {
      return absl::InvalidArgumentError(
          Cat("field name '", field.name, "' must be non-empty and without spaces"));
    }
    if (field.components < 1 ||
        field.values.size() != static_cast<size_t>(nv) * static_cast<size_t>(field.components)) {
      return absl::InvalidArgumentError(Cat("field '", field.name, "' has ", field.values.size(),
                                            " values: expected ", nv, " vertices x ",
                                            field.components, " components"));
    }
  }
  return absl::OkStatus();
}

absl::Status WithPath(const std::string& path, const absl::Status& status) {
  if (status.ok()) return status;
  return absl::Status(
      status.code(),
      Cat(path, ": ", std::string(status.message().data(), status.message().size())));
}

absl::Status WriteFileBytes(const std::string& path, std::string_view bytes) {
  OutputFile out(path);
  if (!out.ok()) return out.status();
  // In pieces, so that OutputFile's buffer stays small for large exports.
  constexpr size_t kPiece = 1 << 20;
  for (size_t at = 0; at < bytes.size() && out.ok(); at += kPiece) {
    out.Put(bytes.substr(at, kPiece));
  }
  absl::Status status = out.Close();
  if (!status.ok()) std::remove(path.c_str());
  return status;
}

void AppendShortest(std::string& out, double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  out.append(tmp, r.ptr);
}
void AppendShortest(std::string& out, float v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  out.append(tmp, r.ptr);
}
void AppendInt(std::string& out, int64_t v) {
  char tmp[24];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  out.append(tmp, r.ptr);
}

void AppendU8(std::string& out, uint8_t v) { out.push_back(static_cast<char>(v)); }
void AppendU16(std::string& out, uint16_t v) {
  out.push_back(static_cast<char>(v & 0xff));
  out.push_back(static_cast<char>(v >> 8));
}
void AppendU32(std::string& out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(static_cast<char>((v >> (8 * b)) & 0xff));
}
void AppendF32(std::string& out, float v) { AppendU32(out, std::bit_cast<uint32_t>(v)); }
void AppendF64(std::string& out, double v) {
  const uint64_t u = std::bit_cast<uint64_t>(v);
  for (int b = 0; b < 8; ++b) out.push_back(static_cast<char>((u >> (8 * b)) & 0xff));
}

int64_t FanTriangleCount(const mesh::BoundarySurface& surface) {
  int64_t n = 0;
  for (int32_t r = 0; r < surface.faces.rows(); ++r) n += surface.faces.row_size(r) - 2;
  return n;
}

}  // namespace internal

namespace {

using internal::AppendF32;
using internal::AppendF64;
using internal::Cat;
using internal::CheckSurface;
using internal::SurfaceRules;
using internal::WithPath;
using internal::WriteFileBytes;

void PutNumber(std::string& out, double v) { internal::AppendShortest(out, v); }
void PutFloat(std::string& out, float v) { internal::AppendShortest(out, v); }
void PutInt(std::string& out, int64_t v) { internal::AppendInt(out, v); }

// The PLY header of WritePly and WritePlyBinary; `format` is "ascii" or
// "binary_little_endian".
void PutPlyHeader(std::string& out, const mesh::BoundarySurface& surface, std::string_view format) {
  out.append("ply\nformat ").append(format).append(" 1.0\ncomment dynsolid boundary surface\n");
  out.append("element vertex ");
  PutInt(out, surface.positions.rows());
  out.append("\nproperty double x\nproperty double y\nproperty double z\n");
  for (const mesh::VertexField& field : surface.fields) {
    for (int k = 0; k < field.components; ++k) {
      out.append("property float ").append(field.name);
      if (field.components == 3) {
        out.append(k == 0 ? "_x" : k == 1 ? "_y" : "_z");
      } else if (field.components != 1) {
        out.push_back('_');
        PutInt(out, k);
      }
      out.push_back('\n');
    }
  }
  out.append("element face ");
  PutInt(out, surface.faces.rows());
  out.append("\nproperty list uchar int vertex_indices\nend_header\n");
}

}  // namespace

absl::Status ObjBytes(const mesh::BoundarySurface& surface, std::string* out) {
  RETURN_IF_ERROR(CheckSurface(surface, {}));
  const Points& p = surface.positions;
  std::string& o = *out;
  o.append("# dynsolid boundary surface: ");
  PutInt(o, p.rows());
  o.append(" vertices, ");
  PutInt(o, surface.faces.rows());
  o.append(" faces\n");
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    o.append("v ");
    PutNumber(o, p(i, 0));
    o.push_back(' ');
    PutNumber(o, p(i, 1));
    o.push_back(' ');
    PutNumber(o, p(i, 2));
    o.push_back('\n');
  }
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    o.push_back('f');
    for (int32_t v : surface.faces.row(r)) {
      o.push_back(' ');
      PutInt(o, static_cast<int64_t>(v) + 1);
    }
    o.push_back('\n');
  }
  return absl::OkStatus();
}

absl::Status WriteObj(const std::string& path, const mesh::BoundarySurface& surface) {
  std::string bytes;
  RETURN_IF_ERROR(WithPath(path, ObjBytes(surface, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::Status PlyBytes(const mesh::BoundarySurface& surface, std::string* out) {
  RETURN_IF_ERROR(CheckSurface(surface, {.max_face_size = 255}));
  const Points& p = surface.positions;
  std::string& o = *out;
  PutPlyHeader(o, surface, "ascii");
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    PutNumber(o, p(i, 0));
    o.push_back(' ');
    PutNumber(o, p(i, 1));
    o.push_back(' ');
    PutNumber(o, p(i, 2));
    for (const mesh::VertexField& field : surface.fields) {
      for (int k = 0; k < field.components; ++k) {
        o.push_back(' ');
        PutFloat(o, static_cast<float>(field.values[i * field.components + k]));
      }
    }
    o.push_back('\n');
  }
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    PutInt(o, surface.faces.row_size(r));
    for (int32_t v : surface.faces.row(r)) {
      o.push_back(' ');
      PutInt(o, v);
    }
    o.push_back('\n');
  }
  return absl::OkStatus();
}

absl::Status WritePly(const std::string& path, const mesh::BoundarySurface& surface) {
  std::string bytes;
  RETURN_IF_ERROR(WithPath(path, PlyBytes(surface, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::Status PlyBinaryBytes(const mesh::BoundarySurface& surface, std::string* out) {
  RETURN_IF_ERROR(CheckSurface(surface, {.max_face_size = 255, .finite_positions = true}));
  const Points& p = surface.positions;
  size_t components = 0;
  for (const mesh::VertexField& field : surface.fields) components += field.components;
  std::string& o = *out;
  PutPlyHeader(o, surface, "binary_little_endian");
  o.reserve(o.size() + static_cast<size_t>(p.rows()) * (24 + 4 * components) +
            static_cast<size_t>(surface.faces.rows()) + 4 * surface.faces.items.size());
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    for (int k = 0; k < 3; ++k) AppendF64(o, p(i, k));
    for (const mesh::VertexField& field : surface.fields) {
      for (int k = 0; k < field.components; ++k) {
        AppendF32(o, static_cast<float>(field.values[i * field.components + k]));
      }
    }
  }
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    internal::AppendU8(o, static_cast<uint8_t>(surface.faces.row_size(r)));
    for (int32_t v : surface.faces.row(r)) internal::AppendU32(o, static_cast<uint32_t>(v));
  }
  return absl::OkStatus();
}

absl::Status WritePlyBinary(const std::string& path, const mesh::BoundarySurface& surface) {
  std::string bytes;
  RETURN_IF_ERROR(WithPath(path, PlyBinaryBytes(surface, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::Status StlBinaryBytes(const mesh::BoundarySurface& surface, std::string* out) {
  RETURN_IF_ERROR(CheckSurface(
      surface, {.need_faces = true, .finite_positions = true, .float32_positions = true}));
  const int64_t triangles = internal::FanTriangleCount(surface);
  if (triangles > static_cast<int64_t>(UINT32_MAX)) {
    return absl::InvalidArgumentError(
        Cat("surface has ", triangles, " triangles: binary STL holds at most ", UINT32_MAX));
  }
  std::string& o = *out;
  // 80-byte header; it must not start with "solid" (the ASCII STL keyword).
  std::string header =
      Cat("dynsolid boundary surface: binary STL, float32, metres, ", triangles, " triangles");
  header.resize(80, ' ');
  o.reserve(o.size() + 84 + 50 * static_cast<size_t>(triangles));
  o.append(header);
  internal::AppendU32(o, static_cast<uint32_t>(triangles));
  const Points& p = surface.positions;
  auto put_vertex = [&](int32_t v) {
    for (int k = 0; k < 3; ++k) AppendF32(o, static_cast<float>(p(v, k)));
  };
  internal::ForEachFanTriangle(surface, [&](int32_t ia, int32_t ib, int32_t ic) {
    const Eigen::Vector3d a = p.row(ia).transpose();
    const Eigen::Vector3d b = p.row(ib).transpose();
    const Eigen::Vector3d c = p.row(ic).transpose();
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double length = n.norm();
    n = length > 0.0 && std::isfinite(length) ? Eigen::Vector3d(n / length)
                                              : Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) AppendF32(o, static_cast<float>(n[k]));
    put_vertex(ia);
    put_vertex(ib);
    put_vertex(ic);
    internal::AppendU16(o, 0);
  });
  return absl::OkStatus();
}

absl::Status WriteStlBinary(const std::string& path, const mesh::BoundarySurface& surface) {
  std::string bytes;
  RETURN_IF_ERROR(WithPath(path, StlBinaryBytes(surface, &bytes)));
  return WriteFileBytes(path, bytes);
}

}  // namespace dynsolid::io
