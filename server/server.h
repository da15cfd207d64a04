// A running dynsolid server: the Sessions service, gRPC health checking and
// (when available) server reflection on one listening address. Used by the
// dynsolid-server binary and by tests, which start it in-process on port 0.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "server/disk_space.h"
#include "server/replicas.h"
#include "server/session_registry.h"
#include "server/sessions_service.h"
#include "server/work_queue.h"

namespace dynsolid::server {

struct ServerOptions {
  // HOST:PORT to listen on (insecure credentials); port 0 picks a free port.
  std::string listen = "127.0.0.1:50051";
  // HOST:PORT of a plaintext listener serving only the gRPC health service
  // (empty: none): for probes that cannot speak TLS, such as the kubelet's
  // native gRPC probes. It reports what the main port does: SERVING until
  // shutdown starts, NOT_SERVING while the server drains.
  std::string health_listen;
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
  // Memory a session's solid may need at its peak, as estimated from the
  // scene before building (EstimateSessionBytes); past it CreateSession is
  // refused at once with RESOURCE_EXHAUSTED naming both. 0: a quarter of
  // the machine's physical memory (DefaultMaxSessionBytes); -1: no limit.
  int64_t max_session_bytes = 0;
  // BuildLimits::build_memory_factor (--build_memory_factor).
  double build_memory_factor = 1.5;
  // Threads that step each session's solid (0: all cores but one, at least
  // one; see BuildLimits::sim_threads).
  int sim_threads = 0;
  // Threads that build solids (off the gRPC threads).
  int build_threads = 1;
  // Threads that encode watch frames (off the simulation threads).
  int encode_threads = 2;
  // Added to the nice value of the streaming threads: the encoder threads
  // and the threads gRPC starts (its pollers, which also run the reactors
  // of every call, and its executor and timer threads; they inherit the
  // value from the thread that starts the gRPC server). The simulation
  // threads keep the server's priority, so on busy cores frames are
  // skipped rather than steps. 0..19; 0: everything at one priority.
  int stream_nice = 10;
  // And run them under SCHED_IDLE (thread_priority.h): they get only CPU
  // no simulation thread wants, and a waking simulation thread preempts
  // them at once (a raised nice value alone only shrinks their share:
  // measured, it does not keep a saturated loop's rate; server/README.md).
  bool stream_idle = true;
  // How sessions run: watch rates, watchers per session, commands per
  // second per client, answer cache, snapshot period.
  LoopOptions loop;
  // Persist every session under this directory and restore them on start
  // (persistence.h); empty: sessions live in memory only.
  std::string data_dir;
  // With data_dir: below this many bytes available on its file system the
  // disk counts as full (disk_space.h): new sessions are refused and health
  // says NOT_SERVING until a check finds room again. A session's command
  // that cannot reserve its journal space is refused whatever this is.
  int64_t min_free_disk_bytes = 8 << 20;
  // How often the data disk's free space is checked.
  absl::Duration disk_check_interval = absl::Milliseconds(250);
  // TLS: PEM files of the server's certificate chain and private key. Both
  // or neither; empty: plaintext.
  std::string tls_cert_file;
  std::string tls_key_file;
  // The replica set this server belongs to (replicas.h; empty: alone).
  // ReplicaOptions::peer_roots_pem is read from peer_ca_file, or, with TLS
  // and no peer_ca_file, from tls_cert_file.
  ReplicaOptions replicas;
  std::string peer_ca_file;
};

// A quarter of the machine's physical memory (MemTotal in /proc/meminfo,
// else sysconf): one session may take that much at its peak, so a few can
// be built at once and the machine keeps room for the rest.
int64_t DefaultMaxSessionBytes();

class Server {
 public:
  // Checks the options, recovers the sessions of data_dir, and starts
  // serving. InvalidArgument for bad options, NotFound/Internal for TLS
  // files that cannot be read, Unavailable when the address cannot be bound.
  static absl::StatusOr<std::unique_ptr<Server>> Start(const ServerOptions& options);

  ~Server();  // Shutdown(absl::Seconds(5)) unless already shut down
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Sessions recovered from data_dir at start.
  int recovered_sessions() const { return recovered_; }

  // The port actually bound, and "HOST:PORT" with it.
  int port() const { return port_; }
  int health_port() const { return health_port_; }
  const std::string& address() const { return address_; }

  // Stops creating sessions (queued builds finish with UNAVAILABLE), stops
  // every session loop (streams finish with UNAVAILABLE, journals are
  // flushed, a last snapshot is written), lets running calls finish until
  // `deadline` from now and cancels the rest, waits for the gRPC server and
  // joins the build and encoder threads. A build already running is not
  // interrupted: shutdown waits for it. Idempotent.
  void Shutdown(absl::Duration deadline);

  SessionRegistry& registry() { return registry_; }
  // The data disk's state (null without data_dir).
  const std::shared_ptr<DiskSpace>& disk() const { return options_.loop.disk; }

 private:
  Server(const ServerOptions& options, std::unique_ptr<Replicas> replicas);

  const ServerOptions options_;
  std::unique_ptr<Replicas> replicas_;
  SessionRegistry registry_;
  WorkQueue builds_;
  WorkQueue encoders_;
  SessionsService service_;
  int recovered_ = 0;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> health_server_;  // ServerOptions::health_listen
  int health_port_ = 0;
  std::string address_;
  absl::Mutex shutdown_mu_;
  bool shut_down_ ABSL_GUARDED_BY(shutdown_mu_) = false;
  // Checks the data disk every disk_check_interval until shutdown.
  void WatchDisk();
  std::thread disk_thread_;
  absl::Mutex disk_mu_;
  bool disk_stop_ ABSL_GUARDED_BY(disk_mu_) = false;
};

}  // namespace dynsolid::server
