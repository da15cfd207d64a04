// dynsolid-load: N scripted clients against a dynsolid-server, with faults,
// measuring throughput and latency and checking that nothing acknowledged
// was lost, duplicated or reordered (docs/load.md). Links only the client
// library (service proto + gRPC), like every client.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "clients/lib/command_channel.h"
#include "clients/load/proc_stats.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::load {

struct Faults {
  bool disconnect = false;    // command streams dropped mid-stream (every few commands)
  bool stop_reading = false;  // watch streams that never read
  bool malformed = false;     // non-finite, oversized and unauthorized messages
  bool burst = false;         // one client above the server's rate limit
  bool restart = false;       // the server killed (SIGKILL) and restarted mid-run
};
absl::StatusOr<Faults> ParseFaults(const std::string& list);

struct Options {
  // Either an address to use, or a server binary to start (with its own
  // --data_dir, on a free loopback port).
  std::string server;
  std::string server_binary;
  std::string data_dir;                  // with server_binary; empty: a temporary one
  std::vector<std::string> server_args;  // extra flags for the started server
  std::string tls_ca;                    // PEM roots: TLS
  std::string scene = "block3";
  int levels = -1;
  int clients = 8;
  bool shared = true;     // one session for every client (else one each)
  double seconds = 5;     // how long clients send
  double rate = 10;       // commands per second per client
  int64_t max_commands = 0;  // per client (0: no limit)
  uint64_t seed = 1;
  bool edits = false;     // topology edits in the mix
  double watch_hz = 30;
  Faults faults;
  double restart_at = 0.5;  // fraction of the run
  int burst_commands = 300;
  int64_t max_rss_mb = 0;  // a started server above this resident size is a problem (0: no bound)
  bool verbose = false;
};

struct Percentiles {
  int64_t count = 0;
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};

struct Report {
  Options options;
  int64_t sent = 0, acknowledged = 0, applied = 0, rejected = 0;
  double commands_per_second = 0;
  Percentiles ack_ms, visible_ms;
  // Command-to-visible by command kind, and over the kinds that never build
  // a solid (BuildsNothing): what a paint's or an edit's build costs its
  // own command, apart from what the other commands see.
  std::map<std::string, Percentiles> visible_by_kind_ms;
  Percentiles visible_no_build_ms;
  std::map<std::string, int64_t> codes;  // status name -> answers (and stream errors of faults)
  // Per command kind: answers, and the time they held the session's loop
  // (CommandReply.hold_ms), total ms: what the stepping thread spent on
  // commands instead of steps.
  struct Hold {
    int64_t count = 0;
    double total_ms = 0, max_ms = 0;
  };
  std::map<std::string, Hold> hold;
  double frames_per_second = 0;          // mean over watchers
  int64_t frames = 0, frames_skipped = 0;
  int64_t reconnects = 0, resends = 0, rate_limited = 0;
  // The server (GetStats, and /proc when started here).
  double unloaded_steps_per_second = 0, loaded_steps_per_second = 0;
  double step_ms_median = 0, step_ms_p99 = 0;
  int64_t steps_dropped = 0, overruns = 0;
  double time_step = 0;
  double server_cpu_percent = 0;  // mean over the run, of one core
  int64_t server_rss_max_kb = 0, server_rss_end_kb = 0;
  std::vector<std::array<double, 3>> server_samples;  // seconds, cpu %, rss kB
  // Where the CPU went over the run (proc_stats.h), when the server is
  // local and was not restarted: its threads by role (sim, encode, journal;
  // "gRPC and other" for the rest: the builds are below), this tool's own
  // threads (the clients), and the cores the machine kept busy of `cores`.
  std::map<std::string, CpuUse> server_threads;
  CpuUse load_tool;
  // The session's builds off the loop (SessionStats.builds...), per second
  // of the run: wall ms the build thread was busy, its CPU and run-queue
  // wait ms (CpuUse; runs_per_s: builds a second).
  double build_busy_ms_per_s = 0;
  CpuUse builds;
  double busy_cores = 0;
  int cores = 0;
  int restarts = 0;
  // Where the sessions were placed: replica name (Session.replica; "" for
  // a server running alone) -> sessions.
  std::map<std::string, int> sessions_per_replica;
  // Verification against the server's journal (GetCommandLog).
  bool verified = false;
  std::vector<std::string> problems;  // lost, duplicated, reordered, unknown
  double wall_seconds = 0;
};

// Runs the load; OK unless setting up failed (the report's `problems` say
// what the verification found).
absl::StatusOr<Report> Run(const Options& options);

// The journal check of one client: `records` as its command channel kept
// them, `log` as GetCommandLog listed its client id's journal entries (in
// the order applied). Returns the problems, each naming the client, the
// seq and the command: an acknowledged command missing (lost) or there
// twice, entries out of seq order, entries never sent, a status that
// differs from the answer, a command refused for good before it was
// considered. Empty: nothing lost, duplicated or reordered.
std::vector<std::string> CheckAgainstJournal(const std::string& client_id,
                                             const std::vector<client::CommandRecord>& records,
                                             const CommandLog& log);

std::string ReportJson(const Report& r);
std::string ReportMarkdown(const Report& r);

}  // namespace dynsolid::load
