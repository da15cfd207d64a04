// Runs a script against a session: creates or joins the session, watches
// its surface, sends the script's commands (CommandChannel), waits, sleeps,
// snapshots, and gathers what happened into a RunReport (latencies, frame
// counts, final surface, the server's stats).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "clients/lib/stats.h"
#include "absl/time/time.h"
#include "clients/lib/channel.h"
#include "clients/lib/command_channel.h"
#include "clients/lib/script.h"
#include "clients/lib/watcher.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::client {

struct RunOptions {
  // Create a session from exactly one of these, or join `join`.
  std::string builtin_scene;
  std::string scene_text;
  int levels = -1;
  bool start_paused = false;
  SessionRef join;
  // Names this client's commands across reconnects; empty: a random id.
  std::string client_id;
  bool watch = true;
  WatcherOptions watcher;
  // Directory for snapshot files (script "snapshot NAME").
  std::string frames_dir;
  bool write_obj = true;
  bool write_vtu = false;
  // Close the session at the end (default for a session this run created).
  bool close_at_end = true;
  // Continue after a rejected command (default: stop at the first).
  bool keep_going = false;
  // Deadline of a wait line / of each single call.
  absl::Duration wait_timeout = absl::Seconds(120);
  absl::Duration call_timeout = absl::Seconds(120);
  CommandChannelOptions commands;
  // Progress messages (each script line, reconnects); may be empty.
  LogFn log;
};

struct SnapshotFile {
  std::string name;
  int64_t step = 0;
  int line = 0;
  std::vector<std::string> files;
};

struct RunReport {
  Session session;  // as created or joined (token cleared: never in reports)
  std::string token;  // the session's token (for the caller only)
  bool created = false;
  bool closed = false;
  std::string client_id;
  std::string script_file;
  int script_lines = 0;
  std::vector<CommandRecord> commands;
  std::vector<std::string> command_lines;  // "file:line verb" per command
  int reconnects = 0;
  int64_t extra_answers = 0;
  WatcherCounts watch;
  std::vector<SnapshotFile> snapshots;
  // The last surface the watcher held, and the first.
  Surface final_surface;
  Surface first_surface;
  // Reconstruction check (when the session ended paused, so the watcher's
  // last frame and Inspect describe the same step): largest |decoded -
  // exact| per axis, and whether it is within the error bound.
  bool checked = false;
  int64_t check_step = -1;
  std::array<double, 3> check_max_error{};
  bool check_within_bound = false;
  SessionStats stats;
  double wall_seconds = 0;
  // The first error (a rejected command, a failed call); OK when all went well.
  absl::Status status;
};

// Runs `script`; the report is filled as far as the run got (its status
// says why it stopped early). Fails only when no session could be had.
absl::StatusOr<RunReport> RunScript(const ChannelFactory& channels, const Script& script,
                                    const RunOptions& options);

// The report as JSON (docs/client.md "Report").
std::string ReportJson(const RunReport& report);
// A few lines for people.
std::string ReportText(const RunReport& report);


}  // namespace dynsolid::client
