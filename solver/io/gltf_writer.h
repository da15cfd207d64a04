// glTF 2.0 binary (.glb) export of the boundary surface (docs/model.md section
// 7): one scene, one node, one mesh with one TRIANGLES primitive.
//
// Layout (little-endian): the 12-byte GLB header ("glTF", version 2, total
// length), a JSON chunk padded with spaces to 4 bytes, a BIN chunk padded
// with zeros. The BIN chunk holds, each in its own bufferView (4-aligned,
// with its target): POSITION (float32 VEC3, metres as stored, with min and
// max), NORMAL (float32 VEC3, unit: area-weighted vertex normals of the
// fan-triangulated loops), optionally COLOR_0 (float32 VEC3, linear RGB),
// then the indices (uint32, 3 per triangle). Vertices are the surface's, in
// its order; triangles are the loops' fans (see surface_writers.h for the
// convexity assumption), in face order.
//
// Scenes are z-up and glTF is y-up: by default the node carries the
// rotation that turns +z into +y, so viewers show the solid upright while
// the mesh data stays in the simulator's frame.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/mesh/boundary.h"

namespace dynsolid::io {

struct GlbOptions {
  // A field of the surface to show as vertex colours (COLOR_0): viridis over
  // the field's [min, max] (a flat field takes the middle colour); a field
  // of several components by its magnitude. Empty: no colours. The field and
  // its range are recorded in the mesh's "extras".
  std::string color_field;
  // asset.generator.
  std::string generator = "dynsolid";
  // Rotate the node from z-up to glTF's y-up (see above).
  bool z_up = true;
  // A morph-target animation (a replayed session): the positions of the
  // later frames of the same surface (each #vertices x 3, metres) and
  // every frame's time (seconds, increasing; one more than morph_frames:
  // the surface's own positions are the first frame). Frame k > 0 is morph
  // target k - 1 (POSITION and NORMAL offsets from the first frame); one
  // animation's weights step through the targets, one at a time, linear
  // between frames.
  std::vector<Points> morph_frames;
  std::vector<double> morph_times;
};

// Appends the .glb file's bytes to *out. Errors as in surface_writers.h
// (InvalidArgument naming the face or vertex; no faces, non-finite or beyond
// float32 positions are refused), and InvalidArgument for an unknown colour
// field, non-finite values in it, or a file beyond GLB's 4 GiB. Nothing is
// appended on error.
absl::Status GlbBytes(const mesh::BoundarySurface& surface, const GlbOptions& options,
                      std::string* out);

// Writes the .glb file (nothing written on error; the path prefixes messages).
absl::Status WriteGlb(const std::string& path, const mesh::BoundarySurface& surface,
                      const GlbOptions& options = {});

// The colour map of COLOR_0: viridis at t in [0, 1] (clamped; NaN is 0),
// interpolated in sRGB between the web viewer's stops
// (clients/web/public/js/colormap.js), returned as linear RGB as glTF
// vertex colours are.
std::array<float, 3> ViridisLinearRgb(double t);

}  // namespace dynsolid::io
