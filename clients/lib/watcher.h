// Watches a session's surface on a background thread: reads the Watch
// stream, rebuilds the surface (SurfaceDecoder), optionally records frames
// to files, counts frames, bytes and skips, and reconnects (with a fresh
// keyframe) when the stream breaks.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"
#include "clients/lib/channel.h"
#include "clients/lib/surface.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::client {

struct WatcherOptions {
  double rate_hz = 0;  // 0: the server's --watch_hz
  bool displacement = false;
  bool strain = false;
  bool stiffness = false;
  bool mass = false;
  // The client_id of this client's command channel (WatchRequest.client_id):
  // a frame follows each of its own commands at once; empty: every
  // client's commands.
  std::string client_id;
  // Record every n-th frame received (0: none) into frames_dir as
  // frame_<step>.obj / .vtu.
  int record_every = 0;
  std::string frames_dir;
  bool write_obj = true;
  bool write_vtu = false;
  absl::Duration reconnect_timeout = absl::Seconds(30);
  // Progress messages (reconnects); may be empty.
  LogFn log;
  // Called on the watcher's thread for every frame decoded, with its step
  // and when it arrived (a load tester's command-to-visible latency); may
  // be empty.
  std::function<void(int64_t step, std::chrono::steady_clock::time_point at)> on_frame;
};

struct WatcherCounts {
  int64_t frames = 0;
  int64_t keyframes = 0;
  int64_t deltas = 0;
  // Sum of Frame.skipped: frames the server published that this watcher
  // did not get (it was still busy with an earlier one).
  int64_t skipped = 0;
  int64_t bytes = 0;  // serialized Frame bytes received
  // Of those, the per-vertex field values (4 bytes each).
  int64_t field_bytes = 0;
  // Bytes the same frames would take as raw float32 positions (12 per
  // vertex), for comparison.
  int64_t raw_float32_bytes = 0;
  int64_t reconnects = 0;
  int64_t first_step = -1;
  int64_t last_step = -1;
  double seconds = 0;  // wall time from the first frame to the last
  int64_t frames_written = 0;
  std::vector<std::string> files;  // recorded frame files
};

class Watcher {
 public:
  // `channels` makes the channel of each stream (a new one per reconnect).
  Watcher(ChannelFactory channels, SessionRef session, WatcherOptions options);
  ~Watcher();
  Watcher(const Watcher&) = delete;
  Watcher& operator=(const Watcher&) = delete;

  // Waits until the watcher holds a surface at step >= `step`. Returns it.
  absl::StatusOr<Surface> WaitForStep(int64_t step, absl::Duration timeout);
  // The current surface (step -1 before the first keyframe).
  Surface Current() const;
  // The first surface received (the reference for displacements).
  Surface First() const;
  WatcherCounts Counts() const;
  // Stops the stream and the thread; returns the stream's error, if it
  // failed for good (OK after a normal stop).
  absl::Status Stop();

 private:
  void Loop();
  void Record(const Surface& s);

  const ChannelFactory channels_;
  const SessionRef session_;
  const WatcherOptions options_;

  mutable absl::Mutex mu_;
  SurfaceDecoder decoder_ ABSL_GUARDED_BY(mu_);
  Surface first_ ABSL_GUARDED_BY(mu_);
  WatcherCounts counts_ ABSL_GUARDED_BY(mu_);
  // The recorded VTU frames' index (frames.pvd: ParaView's collection,
  // each frame at its session time), rewritten after each frame.
  std::string pvd_entries_ ABSL_GUARDED_BY(mu_);
  std::chrono::steady_clock::time_point first_time_ ABSL_GUARDED_BY(mu_);
  bool stop_ ABSL_GUARDED_BY(mu_) = false;
  bool ended_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status error_ ABSL_GUARDED_BY(mu_);
  grpc::ClientContext* context_ ABSL_GUARDED_BY(mu_) = nullptr;
  std::thread thread_;
};

}  // namespace dynsolid::client
