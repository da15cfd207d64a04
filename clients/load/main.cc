// dynsolid-load: load tests from scripted clients (docs/load.md).
//   dynsolid-load --server_binary build/release/server/dynsolid-server --clients 8
//     --seconds 5 --faults all --json out.json --markdown out.md
//   dynsolid-load --server HOST:PORT --clients 32 --seconds 30
// Exit codes: 0 nothing lost; 1 a loss, duplicate, reorder or other problem
// (each named on stderr); 2 bad flags or a server that could not be used.
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/str_split.h"
#include "clients/load/load.h"
#include "cmdline/cmdline.h"

ABSL_FLAG(std::string, server, "", "Address of a running dynsolid-server (HOST:PORT)");
ABSL_FLAG(std::string, server_binary, "",
          "Start this dynsolid-server on a free loopback port with its own --data_dir instead");
ABSL_FLAG(std::string, data_dir, "", "With --server_binary: its --data_dir (default: a temporary one)");
ABSL_FLAG(std::string, server_args, "",
          "With --server_binary: more flags for it, space separated (e.g. \"--sim_threads 1\")");
ABSL_FLAG(std::string, tls_ca, "", "PEM root certificates: connect with TLS");
ABSL_FLAG(std::string, scene, "block3", "Built-in scene of the sessions");
ABSL_FLAG(int, levels, -1, "Subdivision levels (-1: the scene's)");
ABSL_FLAG(int, clients, 8, "Scripted clients, each on its own channel");
ABSL_FLAG(bool, shared, true, "One session for every client (false: one session each)");
ABSL_FLAG(double, seconds, 5, "How long the clients send");
ABSL_FLAG(double, rate, 10, "Commands per second per client");
ABSL_FLAG(int64_t, max_commands, 0, "Commands per client at most (0: no limit)");
ABSL_FLAG(uint64_t, seed, 1, "Seed of the command mix");
ABSL_FLAG(bool, edits, false, "Topology edits (extrusions) in the mix");
ABSL_FLAG(double, watch_hz, 30, "Frames per second each client's watcher asks for");
ABSL_FLAG(std::string, faults, "none",
          "Faults, comma separated: disconnect, stop_reading, malformed, burst, restart, all, none");
ABSL_FLAG(double, restart_at, 0.5, "With restart: when, as a fraction of --seconds");
ABSL_FLAG(int, burst_commands, 300, "With burst: commands sent at once by one client");
ABSL_FLAG(int64_t, max_rss_mb, 0,
          "With --server_binary: fail when its resident memory exceeds this many MB (0: no bound)");
ABSL_FLAG(std::string, json, "", "Write the report as JSON here");
ABSL_FLAG(std::string, markdown, "", "Write the report's table row (markdown) here");
ABSL_FLAG(bool, verbose, false, "Progress on stderr");

int main(int argc, char** argv) {
  dynsolid::cmdline::ParseCommandLine(
      argc, argv, "dynsolid-load: load tests of dynsolid-server from scripted clients (docs/load.md)",
      __FILE__);
  if (!absl::GetFlag(FLAGS_server).empty()) {
    dynsolid::cmdline::CheckHostPortOrExit("dynsolid-load", "--server", absl::GetFlag(FLAGS_server),
                                           /*allow_port_zero=*/false, /*allow_uri=*/true);
  }
  dynsolid::load::Options o;
  o.server = absl::GetFlag(FLAGS_server);
  o.server_binary = absl::GetFlag(FLAGS_server_binary);
  o.data_dir = absl::GetFlag(FLAGS_data_dir);
  for (absl::string_view a : absl::StrSplit(absl::GetFlag(FLAGS_server_args), ' ', absl::SkipEmpty())) {
    o.server_args.emplace_back(a);
  }
  o.tls_ca = absl::GetFlag(FLAGS_tls_ca);
  o.scene = absl::GetFlag(FLAGS_scene);
  o.levels = absl::GetFlag(FLAGS_levels);
  o.clients = absl::GetFlag(FLAGS_clients);
  o.shared = absl::GetFlag(FLAGS_shared);
  o.seconds = absl::GetFlag(FLAGS_seconds);
  o.rate = absl::GetFlag(FLAGS_rate);
  o.max_commands = absl::GetFlag(FLAGS_max_commands);
  o.seed = absl::GetFlag(FLAGS_seed);
  o.edits = absl::GetFlag(FLAGS_edits);
  o.watch_hz = absl::GetFlag(FLAGS_watch_hz);
  o.restart_at = absl::GetFlag(FLAGS_restart_at);
  o.burst_commands = absl::GetFlag(FLAGS_burst_commands);
  o.verbose = absl::GetFlag(FLAGS_verbose);
  o.max_rss_mb = absl::GetFlag(FLAGS_max_rss_mb);
  absl::StatusOr<dynsolid::load::Faults> faults = dynsolid::load::ParseFaults(absl::GetFlag(FLAGS_faults));
  if (!faults.ok()) {
    std::fprintf(stderr, "dynsolid-load: %s\n", std::string(faults.status().message()).c_str());
    return 2;
  }
  o.faults = *faults;
  absl::StatusOr<dynsolid::load::Report> r = dynsolid::load::Run(o);
  if (!r.ok()) {
    std::fprintf(stderr, "dynsolid-load: %s\n", r.status().ToString().c_str());
    return 2;
  }
  const std::string json = dynsolid::load::ReportJson(*r), md = dynsolid::load::ReportMarkdown(*r);
  if (!absl::GetFlag(FLAGS_json).empty()) std::ofstream(absl::GetFlag(FLAGS_json)) << json;
  if (!absl::GetFlag(FLAGS_markdown).empty()) std::ofstream(absl::GetFlag(FLAGS_markdown)) << md;
  std::printf("%s", md.c_str());
  std::printf("%lld sent, %lld acknowledged (%lld applied, %lld refused), %lld resends, %lld reconnects, "
              "%d server restarts; journal check: %s\n",
              static_cast<long long>(r->sent), static_cast<long long>(r->acknowledged),
              static_cast<long long>(r->applied), static_cast<long long>(r->rejected),
              static_cast<long long>(r->resends), static_cast<long long>(r->reconnects), r->restarts,
              !r->verified ? "not done" : r->problems.empty() ? "nothing lost, duplicated or reordered" : "PROBLEMS");
  for (const std::string& p : r->problems) std::fprintf(stderr, "dynsolid-load: %s\n", p.c_str());
  return r->problems.empty() ? 0 : 1;
}
