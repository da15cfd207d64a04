// Animations from a session's journal: the session replayed
// offline, step by step, through the same SimCore code as the live loop
// and crash recovery, with a frame written at each frame time. Because
// the journal replays a session bit for bit, the frames are the shapes the
// live session had at those steps, at any frame rate and subdivision
// level, with no frame dropped (a recording of the watch stream drops
// frames the network could not carry and is quantized to 16 bits).
//
// Output, in out_dir:
//  - PVD: NAME_NNNN.vtu per frame (the volume, design_export.h VTU) and
//    NAME.pvd, the ParaView collection listing each with its time;
//  - OBJ: NAME_NNNN.obj per frame (the boundary surface);
//  - GLB: NAME.glb, one glTF 2.0 file: the first frame's surface and a
//    morph target per later frame, animated by weights at the frames'
//    times (any glTF viewer, Blender). Needs one surface throughout: a
//    topology edit within the range is an error naming its step.
// No gRPC, no server: a file-level tool (dynsolid-replay, replay_main.cc).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"

namespace dynsolid::server {

struct ReplayOptions {
  // The time range, seconds of session time: [from, to]; to < 0: to the
  // journal's end.
  double from = 0, to = -1;
  // Frames per second of session time, > 0 and at most one per step.
  double fps = 30;
  // Subdivision levels of the frames (0-6); -1: the session's.
  int level = -1;
  bool pvd = true, obj = false, glb = false;
  std::string out_dir;
  // File names' stem (empty: the scene's name).
  std::string name;
  // What the live server ran with (its --undo_bytes and --answer_cache):
  // part of a session's determinism.
  CoreOptions core;
  BuildLimits limits;
};

struct ReplayReport {
  int frames = 0;
  std::vector<std::string> files;     // written, in order (the .pvd last)
  std::vector<int64_t> frame_steps;   // the step of each frame
  std::vector<double> frame_times;    // its session time, seconds
  int64_t journal_records = 0;
  // The journal's last step (when the range ended before the journal's
  // last record: at least that record's step).
  int64_t end_step = 0;
  double end_time = 0;
  double milliseconds = 0;
};

// Replays the session in `session_dir` (DATA_DIR/sessions/ID) from step 0
// and writes its frames. Errors, before anything is written:
// InvalidArgument naming the option (a time range outside [0, the
// journal's end], fps out of range or above one frame per step, a level
// outside 0-6 or too fine for the cell limit); NotFound / DataLoss for a
// directory that is not a session's or a journal that does not replay.
absl::StatusOr<ReplayReport> ReplayAnimation(const std::string& session_dir,
                                             const ReplayOptions& options);

}  // namespace dynsolid::server
