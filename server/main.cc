// dynsolid-server: serves dynsolid.Sessions (proto/dynsolid/service.proto).
//
//   dynsolid-server [--listen 127.0.0.1:50051] [--data_dir DIR]
//                   [--tls_cert CERT.pem --tls_key KEY.pem]
//                   [--max_sessions 16] [--max_message_bytes 4194304]
//                   [--max_cells 1000000] [--max_watchers_per_session 64]
//                   [--max_commands_per_second 1000] [--watch_hz 60]
//                   [--max_watch_hz 240] [--answer_cache 256] [--undo_bytes N]
//                   [--snapshot_every_steps 20000] [--build_threads 1]
//                   [--encode_threads 2] [--stream_nice 10] [--stream_idle=true]
//                   [--build_nice 10]
//                   [--replica NAME --advertise HOST:PORT --peers NAME=HOST:PORT,...]
//
// (Abseil flags: --data-dir is spelled --data_dir, --tls-cert --tls_cert,
// and so on.) With --data_dir every session is journaled and snapshotted
// there and restored when the server starts again (server/persistence.h).
//
// The first line of stdout is "listening on HOST:PORT" (the bound port, also
// when --listen asks for port 0), flushed; logs go to stderr. SIGINT or
// SIGTERM shuts down cleanly (running calls get a few seconds). Exit codes:
// 0 after a clean shutdown, 2 bad flags or the address cannot be bound.
#include <csignal>
#include <cstdint>
#include <iostream>
#include <string>

#include <pthread.h>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/synchronization/mutex.h"
#include "cmdline/cmdline.h"
#include "server/log.h"
#include "server/server.h"

ABSL_FLAG(std::string, listen, "127.0.0.1:50051",
          "HOST:PORT to listen on (plaintext); port 0 picks a free port");
ABSL_FLAG(std::string, health_listen, "",
          "HOST:PORT of a plaintext listener serving only the gRPC health service (for probes "
          "that cannot speak TLS, e.g. Kubernetes' gRPC probes); empty: none");
ABSL_FLAG(int, max_sessions, 16, "Most sessions open (or being created) at once");
ABSL_FLAG(int, max_message_bytes, 4 << 20, "Largest gRPC message received or sent, in bytes");
ABSL_FLAG(int64_t, max_cells, 1'000'000,
          "Most level-L cells of a session's solid (checked before building)");
ABSL_FLAG(int64_t, max_session_bytes, 0,
          "Most memory a session's solid may need at its peak, bytes, estimated from the scene "
          "before anything is built (CreateSession is refused at once past it). 0: a quarter "
          "of the machine's physical memory; -1: no limit");
ABSL_FLAG(double, build_memory_factor, 1.5,
          "A solid's build is stopped (CreateSession refused with RESOURCE_EXHAUSTED, nothing "
          "kept) when it grows the server's resident memory past this many times the "
          "session's memory estimate; 0: never");
ABSL_FLAG(int, sim_threads, 0,
          "Threads that step each session's solid (1-8; 0: all cores but one, at least one)");
ABSL_FLAG(int, build_threads, 1, "Threads that build solids, off the gRPC threads");
ABSL_FLAG(int, encode_threads, 2, "Threads that encode watch frames, off the simulation threads");
ABSL_FLAG(int, stream_nice, 10,
          "Added to the nice value of the streaming threads (frame encoders and gRPC's threads, "
          "which also serve commands), 0..19: on busy cores watchers skip frames rather than "
          "the simulation losing steps. 0: one priority for every thread");
ABSL_FLAG(bool, stream_idle, true,
          "Run the streaming threads under SCHED_IDLE as well: only CPU the simulation does not "
          "want, and a waking simulation thread preempts them at once");
ABSL_FLAG(int, build_nice, 10,
          "Added to the nice value of the thread that builds a session's solid off its loop (a "
          "paint, a topology edit, an undo across one), 0..19: on busy cores a build takes "
          "longer rather than the simulation losing steps (bench/reports/load/ANALYSIS.md "
          "measures it). 0: the simulation's priority");
ABSL_FLAG(std::string, data_dir, "",
          "Directory for session journals and snapshots; sessions found there are restored "
          "on start. Empty: sessions live in memory only");
ABSL_FLAG(int64_t, min_free_disk_bytes, int64_t{8} << 20,
          "With --data_dir: below this many bytes available there the data disk counts as full: "
          "new sessions are refused and health says NOT_SERVING until it has room again (a "
          "command that cannot reserve its journal space is refused, not applied, whatever "
          "this is)");
ABSL_FLAG(std::string, tls_cert, "", "PEM certificate chain: serve TLS (with --tls_key)");
ABSL_FLAG(std::string, tls_key, "", "PEM private key of --tls_cert");
ABSL_FLAG(int, max_watchers_per_session, 64, "Most Watch streams open on one session");
ABSL_FLAG(double, max_commands_per_second, 1000,
          "Commands per second per client_id (token bucket with one second of burst)");
ABSL_FLAG(double, watch_hz, 60, "Frames per second for watchers that do not ask for a rate");
ABSL_FLAG(double, max_watch_hz, 240, "Highest frame rate a watcher may ask for");
ABSL_FLAG(int, answer_cache, 256, "Command answers remembered per client for resends");
ABSL_FLAG(int64_t, undo_bytes, int64_t{256} << 20,
          "Bytes each session's undo and redo lists may hold (whole solid states; the oldest "
          "go first). Recover a session with the same value it ran with");
ABSL_FLAG(int64_t, snapshot_every_steps, 20000,
          "With --data_dir, write a snapshot every this many steps (and on shutdown)");
ABSL_FLAG(std::string, replica, "",
          "This replica's name (a-z, 0-9, '-'; e.g. the pod's name): new session ids start "
          "with it (\"NAME.HEX\"), so any replica knows where a session lives. Empty: alone");
ABSL_FLAG(std::string, advertise, "",
          "HOST:PORT clients use to reach this replica (returned in Session.address and in "
          "redirects); empty: the bound address");
ABSL_FLAG(std::string, peers, "",
          "The replica set as NAME=HOST:PORT,... (this replica's entry may be included). "
          "CreateSession places each new session on the least loaded replica; calls for a "
          "peer's session are redirected to it. Needs --replica");
ABSL_FLAG(std::string, peer_ca, "",
          "PEM roots for TLS calls to peers; empty: --tls_cert when serving TLS, else "
          "plaintext");
ABSL_FLAG(double, shutdown_grace_seconds, 5.0,
          "On SIGINT/SIGTERM, how long running calls may take before they are cancelled");

int main(int argc, char** argv) {
  dynsolid::cmdline::ParseCommandLine(
      argc, argv,
      "dynsolid-server [--listen HOST:PORT] [--data_dir DIR] [--tls_cert PEM --tls_key PEM] "
      "[--max_sessions N] [--max_message_bytes B] [--max_watchers_per_session N] "
      "[--max_commands_per_second R] [--watch_hz HZ]",
      __FILE__);
  // Listeners may ask for port 0 (a free port); an address others dial may not.
  dynsolid::cmdline::CheckHostPortOrExit("dynsolid-server", "--listen", absl::GetFlag(FLAGS_listen),
                                         /*allow_port_zero=*/true);
  if (!absl::GetFlag(FLAGS_health_listen).empty()) {
    dynsolid::cmdline::CheckHostPortOrExit("dynsolid-server", "--health_listen",
                                           absl::GetFlag(FLAGS_health_listen), true);
  }
  if (!absl::GetFlag(FLAGS_advertise).empty()) {
    dynsolid::cmdline::CheckHostPortOrExit("dynsolid-server", "--advertise",
                                           absl::GetFlag(FLAGS_advertise), false);
  }
#ifdef NDEBUG
  // Debian's Abseil checks every Mutex acquisition for lock-order cycles
  // (a global graph behind a global lock, also for gRPC's own locks): a
  // debugging aid, measured at about 1.5 % of the server's CPU with 64
  // watchers. Release builds turn it off; debug and sanitizer builds keep it.
  absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore);
#endif

  // Block the shutdown signals in every thread (gRPC's threads inherit the
  // mask) and take them synchronously below.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  dynsolid::server::ServerOptions options;
  options.listen = absl::GetFlag(FLAGS_listen);
  options.health_listen = absl::GetFlag(FLAGS_health_listen);
  options.max_sessions = absl::GetFlag(FLAGS_max_sessions);
  options.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
  options.max_cells = absl::GetFlag(FLAGS_max_cells);
  options.max_session_bytes = absl::GetFlag(FLAGS_max_session_bytes);
  options.build_memory_factor = absl::GetFlag(FLAGS_build_memory_factor);
  options.build_threads = absl::GetFlag(FLAGS_build_threads);
  options.sim_threads = absl::GetFlag(FLAGS_sim_threads);
  options.encode_threads = absl::GetFlag(FLAGS_encode_threads);
  options.stream_nice = absl::GetFlag(FLAGS_stream_nice);
  options.stream_idle = absl::GetFlag(FLAGS_stream_idle);
  options.data_dir = absl::GetFlag(FLAGS_data_dir);
  options.min_free_disk_bytes = absl::GetFlag(FLAGS_min_free_disk_bytes);
  options.tls_cert_file = absl::GetFlag(FLAGS_tls_cert);
  options.tls_key_file = absl::GetFlag(FLAGS_tls_key);
  options.loop.max_watchers = absl::GetFlag(FLAGS_max_watchers_per_session);
  options.loop.commands_per_second = absl::GetFlag(FLAGS_max_commands_per_second);
  options.loop.watch_hz = absl::GetFlag(FLAGS_watch_hz);
  options.loop.max_watch_hz = absl::GetFlag(FLAGS_max_watch_hz);
  options.loop.core.answer_cache = absl::GetFlag(FLAGS_answer_cache);
  options.loop.core.undo_bytes = absl::GetFlag(FLAGS_undo_bytes);
  options.loop.snapshot_every_steps = absl::GetFlag(FLAGS_snapshot_every_steps);
  options.loop.build_nice = absl::GetFlag(FLAGS_build_nice);
  options.replicas.replica = absl::GetFlag(FLAGS_replica);
  options.replicas.advertise = absl::GetFlag(FLAGS_advertise);
  options.replicas.peers = absl::GetFlag(FLAGS_peers);
  options.peer_ca_file = absl::GetFlag(FLAGS_peer_ca);
  absl::StatusOr<std::unique_ptr<dynsolid::server::Server>> server =
      dynsolid::server::Server::Start(options);
  if (!server.ok()) {
    std::cerr << "dynsolid-server: " << server.status().message() << "\n";
    return 2;
  }
  std::cout << "listening on " << (*server)->address() << std::endl;

  int signal = 0;
  sigwait(&signals, &signal);
  dynsolid::server::ServerLog().info("received {}", signal == SIGINT ? "SIGINT" : "SIGTERM");
  (*server)->Shutdown(absl::Seconds(absl::GetFlag(FLAGS_shutdown_grace_seconds)));
  return 0;
}
