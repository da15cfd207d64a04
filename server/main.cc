// dynsolid-server: serves dynsolid.Sessions (proto/dynsolid/service.proto).
//
//   dynsolid-server [--listen 127.0.0.1:50051] [--max_sessions 16]
//                   [--max_message_bytes 4194304] [--max_cells 1000000]
//                   [--build_threads 1]
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
#include "server/log.h"
#include "server/server.h"

ABSL_FLAG(std::string, listen, "127.0.0.1:50051",
          "HOST:PORT to listen on (plaintext); port 0 picks a free port");
ABSL_FLAG(int, max_sessions, 16, "Most sessions open (or being created) at once");
ABSL_FLAG(int, max_message_bytes, 4 << 20, "Largest gRPC message received or sent, in bytes");
ABSL_FLAG(int64_t, max_cells, 1'000'000,
          "Most level-L cells of a session's solid (checked before building)");
ABSL_FLAG(int, build_threads, 1, "Threads that build solids, off the gRPC threads");
ABSL_FLAG(double, shutdown_grace_seconds, 5.0,
          "On SIGINT/SIGTERM, how long running calls may take before they are cancelled");

int main(int argc, char** argv) {
  absl::SetProgramUsageMessage(
      "dynsolid-server [--listen HOST:PORT] [--max_sessions N] [--max_message_bytes B]");
  absl::ParseCommandLine(argc, argv);

  // Block the shutdown signals in every thread (gRPC's threads inherit the
  // mask) and take them synchronously below.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  dynsolid::server::ServerOptions options;
  options.listen = absl::GetFlag(FLAGS_listen);
  options.max_sessions = absl::GetFlag(FLAGS_max_sessions);
  options.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
  options.max_cells = absl::GetFlag(FLAGS_max_cells);
  options.build_threads = absl::GetFlag(FLAGS_build_threads);
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
