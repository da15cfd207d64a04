// Boundary-surface frames for watchers (service.proto "Watch"): the
// immutable snapshot the simulation thread publishes, the per-watcher
// encoder (keyframes and 16-bit quantized deltas against the last frame
// that watcher received) and the matching decoder (tests, tools).
//
// Thread-safety: a SurfaceSnapshot is immutable once published and shared
// by shared_ptr<const>; an encoder or decoder belongs to one watcher and is
// used by one thread at a time.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::server {

// Surface connectivity: changes only with topology_version.
struct SurfaceTopology {
  int64_t version = 0;
  int32_t vertex_count = 0;
  std::vector<int32_t> quads;  // 4 per quad, outward
  std::vector<int32_t> nodes;  // fine-mesh node per surface vertex
};

// One published state of the surface, at a step boundary.
struct SurfaceSnapshot {
  int64_t step = 0;
  double time = 0;
  int64_t fields_version = 0;
  std::shared_ptr<const SurfaceTopology> topology;
  std::vector<double> positions;  // 3 per vertex, metres
  // Per-vertex fields; empty when no watcher asked for them.
  std::vector<float> displacement, strain, stiffness;
};

struct FieldChoice {
  bool displacement = false;
  bool strain = false;
  bool stiffness = false;
  bool any() const { return displacement || strain || stiffness; }
};

// The quantization grid of a keyframe (service.proto QuantizationGrid).
struct Grid {
  std::array<double, 3> origin{};
  std::array<double, 3> step{};
  double Decode(int axis, uint32_t code) const { return origin[axis] + code * step[axis]; }
};

inline constexpr uint32_t kMaxCode = 65535;

// The grid for positions (3 per vertex): the bounding box widened by 25 %
// of its extent per axis (at least 1e-3 of the largest extent, or 1e-3 m for
// a point), 65535 steps across.
Grid GridFor(const std::vector<double>& positions);

class SurfaceEncoder {
 public:
  explicit SurfaceEncoder(FieldChoice fields) : fields_(fields) {}
  SurfaceEncoder(const SurfaceEncoder&) = delete;
  SurfaceEncoder& operator=(const SurfaceEncoder&) = delete;

  // Fills `frame` (step, time, body) with `snapshot` encoded against the
  // previous frame this encoder produced, which the caller promises was
  // delivered (the write completed). Returns whether it is a keyframe.
  bool Encode(const SurfaceSnapshot& snapshot, Frame* frame);

 private:
  void EncodeKeyframe(const SurfaceSnapshot& s, const std::vector<uint16_t>* codes, Frame* frame);

  const FieldChoice fields_;
  bool has_base_ = false;
  int64_t base_step_ = 0;
  int64_t topology_version_ = 0;
  int64_t fields_version_ = 0;
  Grid grid_;
  std::vector<uint16_t> codes_;  // 3 per vertex: what the watcher holds
};

// Rebuilds positions from a watcher's frames.
class SurfaceDecoder {
 public:
  // Applies one frame. FailedPrecondition for a delta without a keyframe or
  // whose base_step is not the last frame's step; InvalidArgument for a
  // malformed frame.
  absl::Status Apply(const Frame& frame);

  bool has_keyframe() const { return has_keyframe_; }
  int64_t step() const { return step_; }
  int64_t topology_version() const { return topology_version_; }
  // 3 per vertex, decoded in double precision.
  std::vector<double> Positions() const;
  const std::vector<int32_t>& quads() const { return quads_; }
  const Vec3& error_bound() const { return error_bound_; }
  const std::vector<float>& displacement() const { return displacement_; }
  const std::vector<float>& strain() const { return strain_; }
  const std::vector<float>& stiffness() const { return stiffness_; }

 private:
  bool has_keyframe_ = false;
  int64_t step_ = 0;
  int64_t topology_version_ = 0;
  Grid grid_;
  Vec3 error_bound_;
  std::vector<int32_t> quads_;
  std::vector<uint32_t> codes_;
  std::vector<float> displacement_, strain_, stiffness_;
};

}  // namespace dynsolid::server
