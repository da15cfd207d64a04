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
#include <string>
#include <vector>

#include <deque>
#include <utility>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/synchronization/mutex.h"
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
  std::vector<float> displacement, strain, stiffness, mass;
};

struct FieldChoice {
  bool displacement = false;
  bool strain = false;
  bool stiffness = false;
  bool mass = false;
  bool any() const { return displacement || strain || stiffness || mass; }
  // How many are chosen (each costs 4 bytes per vertex sent).
  int count() const { return displacement + strain + stiffness + mass; }
  // One bit per field (EncodeCache::Key::fields).
  int bits() const { return displacement + 2 * strain + 4 * stiffness + 8 * mass; }
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

// Whether every position quantizes on `grid` and the positions span at
// least a quarter of the grid on its largest axis (else a keyframe with a
// new grid is due).
bool GridFits(const Grid& grid, const std::vector<double>& positions);

// Shares encoding work between the watchers of one session. A watcher's
// state is a function of (its grid, the snapshot of its last frame): its
// codes are that snapshot quantized on that grid. Watchers in the same
// state that encode the same snapshot therefore produce the same frame
// body, which the first one computes and the others copy. The cache also
// keeps the session's current keyframe grid, so watchers that key at
// different times converge on one grid (and then share work).
// Thread-safe.
class EncodeCache {
 public:
  struct Key {
    const SurfaceSnapshot* snapshot = nullptr;
    const SurfaceSnapshot* base = nullptr;  // nullptr: no base (keyframe)
    int64_t grid_id = -1;
    int fields = 0;  // FieldChoice bits
    bool operator==(const Key& o) const {
      return snapshot == o.snapshot && base == o.base && grid_id == o.grid_id &&
             fields == o.fields;
    }
  };
  struct Result {
    Frame frame;  // step, time, body (no skipped / watcher_id)
    // `frame` serialized once for every watcher that sends it (fields 1-4
    // in field order; a watcher appends FrameTrailer).
    std::shared_ptr<const std::string> bytes;
    bool keyframe = false;
    int64_t grid_id = 0;
    Grid grid;
    std::shared_ptr<const std::vector<uint16_t>> codes;
    // Keeps the snapshots named by the key alive (their addresses are the key).
    std::shared_ptr<const SurfaceSnapshot> snapshot, base;
  };

  EncodeCache() = default;
  EncodeCache(const EncodeCache&) = delete;
  EncodeCache& operator=(const EncodeCache&) = delete;

  std::shared_ptr<const Result> Find(const Key& key);
  void Insert(const Key& key, std::shared_ptr<const Result> result);
  // The grid for a keyframe of `positions`: the current one while it fits
  // (GridFits), else a new GridFor(positions), which becomes current.
  std::pair<int64_t, Grid> KeyGrid(const std::vector<double>& positions);

  int64_t hits() const;
  int64_t misses() const;

 private:
  static constexpr size_t kMaxEntries = 512;
  mutable absl::Mutex mu_;
  std::deque<std::pair<Key, std::shared_ptr<const Result>>> entries_ ABSL_GUARDED_BY(mu_);
  int64_t grid_id_ ABSL_GUARDED_BY(mu_) = 0;  // 0: none yet
  Grid grid_ ABSL_GUARDED_BY(mu_);
  int64_t hits_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t misses_ ABSL_GUARDED_BY(mu_) = 0;
};

class SurfaceEncoder {
 public:
  // `cache` may be null (no sharing).
  explicit SurfaceEncoder(FieldChoice fields, std::shared_ptr<EncodeCache> cache = nullptr)
      : fields_(fields), cache_(std::move(cache)) {}
  SurfaceEncoder(const SurfaceEncoder&) = delete;
  SurfaceEncoder& operator=(const SurfaceEncoder&) = delete;

  // Fills `frame` (step, time, body) with `snapshot` encoded against the
  // previous frame this encoder produced, which the caller promises was
  // delivered (the write completed). Returns whether it is a keyframe.
  bool Encode(std::shared_ptr<const SurfaceSnapshot> snapshot, Frame* frame);
  // The same without a copy: the shared result (frame, keyframe flag and
  // the frame's bytes), one object for every watcher in the same state.
  std::shared_ptr<const EncodeCache::Result> EncodeShared(
      std::shared_ptr<const SurfaceSnapshot> snapshot);

 private:
  // The frame for `s` from this encoder's state; changes no member.
  std::shared_ptr<EncodeCache::Result> Compute(const SurfaceSnapshot& s) const;
  void MakeKeyframe(const SurfaceSnapshot& s, EncodeCache::Result* r) const;

  const FieldChoice fields_;
  const std::shared_ptr<EncodeCache> cache_;
  // The last frame's snapshot, grid and codes (3 per vertex: what the
  // watcher holds).
  std::shared_ptr<const SurfaceSnapshot> base_;
  int64_t grid_id_ = -1;
  Grid grid_;
  std::shared_ptr<const std::vector<uint16_t>> codes_;
};

// The per-watcher fields of a Frame (skipped = 5, watcher_id = 6) in wire
// format. EncodeCache::Result::bytes followed by these bytes is exactly the
// serialization of that frame with those fields set (protobuf merges
// concatenated messages; the fields come in field-number order), so one
// serialized body serves every watcher.
std::string FrameTrailer(int64_t skipped, int64_t watcher_id);

// The decoder is the client library's (clients/lib/surface.h): one for the
// C++ side, which the server's tests run on its frames.

}  // namespace dynsolid::server
