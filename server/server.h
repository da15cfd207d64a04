// A running dynsolid server: the Sessions service, gRPC health checking and
// (when available) server reflection on one listening address. Used by the
// dynsolid-server binary and by tests, which start it in-process on port 0.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "server/session_registry.h"
#include "server/sessions_service.h"
#include "server/work_queue.h"

namespace dynsolid::server {

struct ServerOptions {
  // HOST:PORT to listen on (insecure credentials); port 0 picks a free port.
  std::string listen = "127.0.0.1:50051";
  // Open sessions (plus creations in progress) at most.
  int max_sessions = 16;
  // Largest message received or sent, in bytes.
  int max_message_bytes = 4 << 20;
  // Level-L cells a session's solid may have at most (estimated before
  // building; see EstimateFineCells). A built solid keeps about 1.4 KB per
  // cell and needs about twice that while building (chair at 4 levels:
  // 311k cells, 430 MB), so memory is bounded by roughly
  // max_sessions * max_cells * 1.4 KB. The default admits every built-in
  // scene at 4 levels (bridge, the largest: 631k cells).
  int64_t max_cells = 1'000'000;
  // Threads that build solids (off the gRPC threads).
  int build_threads = 1;
};

class Server {
 public:
  // Checks the options and starts serving. InvalidArgument for bad options,
  // Unavailable when the address cannot be bound.
  static absl::StatusOr<std::unique_ptr<Server>> Start(const ServerOptions& options);

  ~Server();  // Shutdown(absl::Seconds(5)) unless already shut down
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The port actually bound, and "HOST:PORT" with it.
  int port() const { return port_; }
  const std::string& address() const { return address_; }

  // Stops creating sessions (queued builds finish with UNAVAILABLE), lets
  // running calls finish until `deadline` from now and cancels the rest,
  // waits for the gRPC server and joins the build threads. A build already
  // running is not interrupted: shutdown waits for it. Idempotent.
  void Shutdown(absl::Duration deadline);

  SessionRegistry& registry() { return registry_; }

 private:
  explicit Server(const ServerOptions& options);

  const ServerOptions options_;
  SessionRegistry registry_;
  WorkQueue builds_;
  SessionsService service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::string address_;
  absl::Mutex shutdown_mu_;
  bool shut_down_ ABSL_GUARDED_BY(shutdown_mu_) = false;
};

}  // namespace dynsolid::server
