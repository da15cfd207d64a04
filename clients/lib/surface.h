// The watched boundary surface on the client side: rebuilding positions
// from a Watch stream's keyframes and quantized deltas (service.proto
// "Watch"), and writing a surface as OBJ or VTK XML .vtu.
//
// Written from the wire format documented in service.proto only; the
// client shares no code with the server's encoder, so the loopback tests
// check one against the other.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::client {

// A decoded surface at one step.
struct Surface {
  int64_t step = -1;
  double time = 0;
  int64_t topology_version = 0;
  // 3 per vertex, metres (decoded in double precision).
  std::vector<double> positions;
  // 4 per quad, outward.
  std::vector<int32_t> quads;
  // The fine-mesh node of each vertex.
  std::vector<int32_t> nodes;
  // Per-vertex fields; each empty or one value per vertex.
  std::vector<float> displacement, strain, stiffness, mass;
  // Half a grid step per axis, metres.
  std::array<double, 3> error_bound{};

  int vertex_count() const { return static_cast<int>(positions.size() / 3); }
  // Axis-aligned bounds of the positions (zeros for an empty surface).
  std::array<double, 3> BoundsMin() const;
  std::array<double, 3> BoundsMax() const;
};

// Applies the frames of one Watch stream in order.
class SurfaceDecoder {
 public:
  SurfaceDecoder() = default;
  SurfaceDecoder(const SurfaceDecoder&) = delete;
  SurfaceDecoder& operator=(const SurfaceDecoder&) = delete;

  // Applies one frame. On error nothing changes: FailedPrecondition for a
  // delta before any keyframe or whose base_step is not the step of the
  // last frame applied; InvalidArgument for a malformed frame (message names
  // the field).
  absl::Status Apply(const Frame& frame);

  // Forget everything (a new stream starts with a keyframe).
  void Reset();

  bool has_keyframe() const { return has_keyframe_; }
  int64_t step() const { return surface_.step; }
  // The current surface (positions decoded from the codes).
  const Surface& surface() const { return surface_; }

 private:
  absl::Status ApplyKeyframe(const Frame& frame);
  absl::Status ApplyDelta(const Frame& frame);
  void DecodePositions(const std::vector<int>& which);

  bool has_keyframe_ = false;
  std::array<double, 3> origin_{};
  std::array<double, 3> step_{};
  std::vector<uint16_t> codes_;  // 3 per vertex
  Surface surface_;
};

// Writes `s` as Wavefront OBJ (v lines, then quads as 1-based f lines).
absl::Status WriteObj(const Surface& s, const std::string& path);
// Writes `s` as a VTK XML UnstructuredGrid (.vtu, ASCII): quads, and
// point data "node" and every non-empty field (displacement, strain,
// stiffness, mass).
absl::Status WriteVtu(const Surface& s, const std::string& path);

}  // namespace dynsolid::client
