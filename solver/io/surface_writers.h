// Writers of the boundary surface (MODEL.md section 7) for rendering and
// export. Both write ASCII, positions in metres as stored, faces as the
// surface's outward loops (polygons of any size, not triangulated).
//
// Errors: InvalidArgument when the surface is inconsistent (a loop index
// out of range, a field of the wrong size, a polygon too large for PLY);
// NotFound / PermissionDenied / Internal when the file cannot be written.
// Nothing is written for an inconsistent surface.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "solver/mesh/boundary.h"

namespace dynsolid::io {

// Wavefront OBJ: "v x y z" per vertex, "f a b c ..." per face (1-based).
// Per-vertex fields are not written (OBJ has no place for them).
absl::Status WriteObj(const std::string& path, const mesh::BoundarySurface& surface);

// PLY 1.0 ASCII: element vertex with `double x, y, z` and one `float`
// property per field component (a 1-component field is `name`, a
// 3-component one `name_x name_y name_z`, any other count `name_0 ...`);
// element face with `property list uchar int vertex_indices` (so at most
// 255 vertices per face). Field names must be non-empty without spaces.
absl::Status WritePly(const std::string& path, const mesh::BoundarySurface& surface);

}  // namespace dynsolid::io
