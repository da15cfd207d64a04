// The load report's figures (private to dynsolid-load): what the clients
// and the fault threads brought back, and the server's stats before and
// after, summed into a Report (load.h). ReportJson and ReportMarkdown
// (load.h) write it; they live in report.cc too.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "clients/lib/command_channel.h"
#include "clients/lib/watcher.h"
#include "clients/load/load.h"
#include "clients/load/proc_stats.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::load {

// What one client (or fault thread) brought back.
struct ClientResult {
  std::vector<client::CommandRecord> records;
  std::vector<std::pair<int64_t, std::chrono::steady_clock::time_point>> frames;
  client::WatcherCounts watch;
  int reconnects = 0;
  std::vector<std::string> problems;
  std::map<std::string, int64_t> fault_codes;
};

// The threads' CPU times as the run starts and just before it ends, over
// `seconds` between them (server_pid 0: no server started here).
struct CpuWindow {
  pid_t server_pid = 0;
  CpuSnapshot server0, tool0, server1, tool1;
  double seconds = 0;
};

// A gRPC status code's name ("RESOURCE_EXHAUSTED"; "CODE_N" past the known).
std::string CodeName(int code);
// The command's kind as its field name ("add_point_force"; "none" unset).
std::string KindName(const Command& c);

// Counts, codes, hold times and latency percentiles from the clients'
// records and frames (each client's frames are sorted by arrival here);
// the fault threads' problems and codes and the burst's answers. With
// o.verbose, every refused command on stderr.
void ClientFigures(const Options& o, std::vector<ClientResult>& results,
                   const std::vector<ClientResult>& fault_results,
                   const std::vector<client::CommandRecord>& burst_records, double run_seconds,
                   Report& rep);

// Step rates and times between `before` and `after` (the first session's),
// the server's CPU and memory from its samples, and where the CPU went.
// After a restart the server's counters began again: its drops, overruns,
// builds and threads are then not differences over the run.
void ServerFigures(const SessionStats& before, const SessionStats& after, const CpuWindow& cpu,
                   int restarts, double run_seconds, Report& rep);

}  // namespace dynsolid::load
