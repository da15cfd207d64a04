// Writers of the boundary surface (docs/model.md section 7) for rendering and
// export, positions in metres as stored:
//   OBJ and PLY (ASCII), binary PLY: the surface's outward loops as
//     polygons of any size (not triangulated);
//   binary STL and glTF binary (.glb, solver/io/gltf_writer.h): triangles.
//
// Each format has a file writer (Write*) and an in-memory one (*Bytes) that
// appends the file's exact bytes to a std::string (the server streams
// exports in chunks); the file writers call the in-memory ones.
//
// Triangulation (STL, glTF): each loop v0 v1 ... v(n-1) becomes the fan
// (v0, vi, vi+1), i = 1 .. n-2, so n - 2 triangles with the loop's winding.
// This assumes convex (or at least star-shaped from v0) loops, which the
// surfaces of our cell complexes and their subdivisions have (quads and
// small convex polygons). For any loop the fan's vector area equals the
// loop's, so enclosed volumes stay right even where a triangle overlaps.
//
// Errors: InvalidArgument when the surface is inconsistent (a loop index
// out of range, a field of the wrong size, a polygon too large for PLY) and,
// for the binary writers, when a position is not finite (or, for float32
// formats, beyond float32's range) or (STL, glTF) there are no faces;
// NotFound / PermissionDenied / Internal when the file cannot be written.
// Messages name the face, vertex or field (file writers prefix the path).
// Nothing is written (or appended) for an inconsistent surface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "solver/mesh/boundary.h"

namespace dynsolid::io {

// Wavefront OBJ: "v x y z" per vertex, "f a b c ..." per face (1-based).
// Per-vertex fields are not written (OBJ has no place for them).
absl::Status WriteObj(const std::string& path, const mesh::BoundarySurface& surface);
absl::Status ObjBytes(const mesh::BoundarySurface& surface, std::string* out);

// PLY 1.0 ASCII: element vertex with `double x, y, z` and one `float`
// property per field component (a 1-component field is `name`, a
// 3-component one `name_x name_y name_z`, any other count `name_0 ...`);
// element face with `property list uchar int vertex_indices` (so at most
// 255 vertices per face). Field names must be non-empty without spaces.
absl::Status WritePly(const std::string& path, const mesh::BoundarySurface& surface);
absl::Status PlyBytes(const mesh::BoundarySurface& surface, std::string* out);

// PLY 1.0 binary_little_endian: the same header (elements, properties,
// their types and names) as WritePly, then the same records in binary:
// per vertex x y z as float64 and each field component as float32, per face
// a uint8 count and int32 indices. Refuses non-finite positions.
absl::Status WritePlyBinary(const std::string& path, const mesh::BoundarySurface& surface);
absl::Status PlyBinaryBytes(const mesh::BoundarySurface& surface, std::string* out);

// Binary STL: an 80-byte header (text "dynsolid boundary surface ...", not
// starting with "solid"), a uint32 triangle count (sum over loops of
// size - 2), then per triangle the unit facet normal from its winding
// (right-hand rule, so outward for outward loops; 0 0 0 for a degenerate
// triangle), its three vertices, all float32, and a uint16 0. Little-endian.
// Fields are not written. Refuses a surface with no faces, a non-finite
// position or one beyond float32's range.
absl::Status WriteStlBinary(const std::string& path, const mesh::BoundarySurface& surface);
absl::Status StlBinaryBytes(const mesh::BoundarySurface& surface, std::string* out);

namespace internal {

// Shared by the surface writers (here and gltf_writer.cc); not public API.
struct SurfaceRules {
  size_t max_face_size = SIZE_MAX;
  bool need_faces = false;         // refuse a surface without faces
  bool finite_positions = false;   // refuse NaN / infinite coordinates
  bool float32_positions = false;  // refuse coordinates beyond float32
};
// OK or InvalidArgument("surface ...") naming the face, vertex or field.
absl::Status CheckSurface(const mesh::BoundarySurface& surface, const SurfaceRules& rules);

// `status` with "path: " before its message (OK stays OK).
absl::Status WithPath(const std::string& path, const absl::Status& status);
// Writes `bytes` to `path` (the errors of OutputFile in text_file.h); a
// partly written file is removed.
absl::Status WriteFileBytes(const std::string& path, std::string_view bytes);

// Text numbers: the shortest text that reads back to the same value (as
// OutputFile writes them).
void AppendShortest(std::string& out, double v);
void AppendShortest(std::string& out, float v);
void AppendInt(std::string& out, int64_t v);

// Little-endian binary appenders.
void AppendU8(std::string& out, uint8_t v);
void AppendU16(std::string& out, uint16_t v);
void AppendU32(std::string& out, uint32_t v);
void AppendF32(std::string& out, float v);
void AppendF64(std::string& out, double v);

// Calls fn(a, b, c) for each fan triangle of the surface's loops, in loop
// order: (l0, l_i, l_i+1) for i = 1 .. size - 2 (the loops' triangulation
// every writer uses).
template <typename Fn>
void ForEachFanTriangle(const mesh::BoundarySurface& surface, Fn&& fn) {
  for (int32_t r = 0; r < surface.faces.rows(); ++r) {
    const auto loop = surface.faces.row(r);
    for (size_t i = 1; i + 1 < loop.size(); ++i) fn(loop[0], loop[i], loop[i + 1]);
  }
}

// Number of fan triangles of the surface's loops (sum of size - 2).
int64_t FanTriangleCount(const mesh::BoundarySurface& surface);

}  // namespace internal
}  // namespace dynsolid::io
