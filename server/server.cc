#include "server/server.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include "absl/strings/str_cat.h"
#include "cmdline/cmdline.h"
#include "server/journal.h"
#include "server/log.h"
#include "server/thread_priority.h"

namespace dynsolid::server {
namespace {

// The HOST part of "HOST:PORT" ("[::1]:0" -> "[::1]").
std::string HostOf(const std::string& listen) {
  const size_t colon = listen.rfind(':');
  return colon == std::string::npos ? listen : listen.substr(0, colon);
}

absl::Status CheckOptions(const ServerOptions& o) {
  if (absl::Status s = cmdline::CheckHostPort("listen", o.listen, /*allow_port_zero=*/true);
      !s.ok()) {
    return s;
  }
  if (!o.health_listen.empty()) {
    if (absl::Status s = cmdline::CheckHostPort("health_listen", o.health_listen, true); !s.ok()) {
      return s;
    }
  }
  if (o.max_sessions < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_sessions must be >= 1, got ", o.max_sessions));
  }
  if (o.max_message_bytes < 1024) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_message_bytes must be >= 1024, got ", o.max_message_bytes));
  }
  if (o.max_cells < 1) {
    return absl::InvalidArgumentError(absl::StrCat("max_cells must be >= 1, got ", o.max_cells));
  }
  if (!(o.build_memory_factor >= 0) || !std::isfinite(o.build_memory_factor)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "build_memory_factor must be finite and >= 0 (0: never stop a build), got ",
        o.build_memory_factor));
  }
  if (o.sim_threads < 0 || o.sim_threads > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("sim_threads must be in 0-8 (0: all cores but one), got ", o.sim_threads));
  }
  if (o.encode_threads < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("encode_threads must be >= 1, got ", o.encode_threads));
  }
  if (!(o.loop.watch_hz > 0) || !(o.loop.max_watch_hz >= o.loop.watch_hz)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "watch_hz must be > 0 and <= max_watch_hz, got ", o.loop.watch_hz, " and ",
        o.loop.max_watch_hz));
  }
  if (o.loop.max_watchers < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_watchers_per_session must be >= 1, got ", o.loop.max_watchers));
  }
  if (!(o.loop.commands_per_second > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_commands_per_second must be > 0, got ", o.loop.commands_per_second));
  }
  if (o.loop.core.answer_cache < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("answer_cache must be >= 1, got ", o.loop.core.answer_cache));
  }
  if (o.tls_cert_file.empty() != o.tls_key_file.empty()) {
    return absl::InvalidArgumentError("tls_cert and tls_key must be given together");
  }
  if (o.stream_nice < 0 || o.stream_nice > 19) {
    return absl::InvalidArgumentError(
        absl::StrCat("stream_nice must be in 0..19, got ", o.stream_nice));
  }
  if (o.loop.build_nice < 0 || o.loop.build_nice > 19) {
    return absl::InvalidArgumentError(
        absl::StrCat("build_nice must be in 0..19, got ", o.loop.build_nice));
  }
  if (o.min_free_disk_bytes < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_free_disk_bytes must be >= 0, got ", o.min_free_disk_bytes));
  }
  if (o.build_threads < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("build_threads must be >= 1, got ", o.build_threads));
  }
  return absl::OkStatus();
}

}  // namespace

int64_t DefaultMaxSessionBytes() {
  int64_t total = 0;
  if (std::FILE* f = std::fopen("/proc/meminfo", "r")) {
    char line[256];
    while (std::fgets(line, sizeof(line), f) != nullptr) {
      long long kb = 0;
      if (std::sscanf(line, "MemTotal: %lld kB", &kb) == 1) {
        total = static_cast<int64_t>(kb) * 1024;
        break;
      }
    }
    std::fclose(f);
  }
  if (total <= 0) {
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0) total = static_cast<int64_t>(pages) * page;
  }
  return total > 0 ? total / 4 : int64_t{4} << 30;
}

Server::Server(const ServerOptions& options, std::unique_ptr<Replicas> replicas)
    : options_(options),
      replicas_(std::move(replicas)),
      registry_(RegistryOptions{
          options.max_sessions,
          BuildLimits{options.max_cells, options.sim_threads,
                      options.max_session_bytes < 0 ? 0 : options.max_session_bytes,
                      options.build_memory_factor},
          options.loop,
          options.data_dir, replicas_->IdPrefix(),
          [r = replicas_.get()](absl::string_view id) { return r->Elsewhere(id); }}),
      builds_(options.build_threads, "build"),
      encoders_(options.encode_threads, "encode", options.stream_nice, options.stream_idle),
      service_(registry_, *replicas_, options.max_sessions, builds_, encoders_,
               StreamOptions{options.loop.watch_hz, options.loop.max_watch_hz}) {}

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const ServerOptions& given) {
  if (absl::Status s = CheckOptions(given); !s.ok()) return s;
  ServerOptions options = given;
  if (options.max_session_bytes == 0) options.max_session_bytes = DefaultMaxSessionBytes();
  if (!options.data_dir.empty()) {
    options.loop.disk = std::make_shared<DiskSpace>(options.data_dir, options.min_free_disk_bytes);
  }
  std::string cert, key;
  if (!options.tls_cert_file.empty()) {
    absl::StatusOr<std::string> c = ReadWholeFile(options.tls_cert_file);
    if (!c.ok()) return c.status();
    absl::StatusOr<std::string> k = ReadWholeFile(options.tls_key_file);
    if (!k.ok()) return k.status();
    cert = *std::move(c);
    key = *std::move(k);
  }
  ReplicaOptions replica_options = options.replicas;
  const std::string& peer_ca = options.peer_ca_file.empty() ? options.tls_cert_file
                                                            : options.peer_ca_file;
  if (!peer_ca.empty() && !replica_options.peers.empty()) {
    absl::StatusOr<std::string> roots = ReadWholeFile(peer_ca);
    if (!roots.ok()) return roots.status();
    replica_options.peer_roots_pem = *std::move(roots);
  }
  absl::StatusOr<std::unique_ptr<Replicas>> replicas = Replicas::Make(replica_options);
  if (!replicas.ok()) return replicas.status();
  if (!options.data_dir.empty()) {
    if (absl::Status s = MakeDirs(options.data_dir + "/sessions"); !s.ok()) return s;
  }
  std::unique_ptr<Server> server(new Server(options, *std::move(replicas)));
  // Recovered sessions' simulation threads start here, at this thread's
  // priority.
  server->recovered_ = server->registry_.RecoverAll();

  // gRPC is started from a thread of lowered priority: the threads it
  // creates (pollers running the reactors, executor, timers) inherit it.
  // (Threads gRPC already runs in this process, e.g. for a client made
  // earlier, keep theirs.)
  absl::Status nice_status;
  std::thread starter([&] {
    nice_status = LowerThisThreadPriority(options.stream_nice);
    if (nice_status.ok() && options.stream_idle) nice_status = MakeThisThreadIdle();
    std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
    if (!options.tls_cert_file.empty()) {
      grpc::SslServerCredentialsOptions ssl;
      ssl.pem_key_cert_pairs.push_back({key, cert});
      credentials = grpc::SslServerCredentials(ssl);
    }
    // Both are process-wide switches read when a server is built.
    grpc::EnableDefaultHealthCheckService(true);
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();

    grpc::ServerBuilder builder;
    builder.AddListeningPort(options.listen, credentials, &server->port_);
    // Fail to start rather than share a port with another process.
    builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    builder.SetMaxReceiveMessageSize(options.max_message_bytes);
    builder.SetMaxSendMessageSize(options.max_message_bytes);
    builder.RegisterService(&server->service_);
    server->server_ = builder.BuildAndStart();
    if (server->server_ != nullptr && !options.health_listen.empty()) {
      // Health only (the default health service every server built here
      // has), in plaintext.
      grpc::ServerBuilder health;
      health.AddListeningPort(options.health_listen, grpc::InsecureServerCredentials(),
                              &server->health_port_);
      health.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
      server->health_server_ = health.BuildAndStart();
    }
  });
  starter.join();
  if (!nice_status.ok()) {
    ServerLog().warn("streaming threads keep the server's priority: {}",
                     std::string(nice_status.message()));
  }
  const bool health_failed = !options.health_listen.empty() &&
                             (server->health_server_ == nullptr || server->health_port_ == 0);
  if (server->server_ == nullptr || server->port_ == 0 || health_failed) {
    server->registry_.StopAll(absl::UnavailableError("the server could not start"));
    server->builds_.Join();
    server->encoders_.Join();
    if (server->server_ != nullptr) server->server_->Shutdown();
    if (server->health_server_ != nullptr) server->health_server_->Shutdown();
    absl::MutexLock lock(&server->shutdown_mu_);
    server->shut_down_ = true;
    return absl::UnavailableError(absl::StrCat(
        "cannot listen on ", health_failed ? options.health_listen : options.listen));
  }
  if (const std::shared_ptr<DiskSpace>& disk = options.loop.disk; disk != nullptr) {
    // Health follows the data disk: NOT_SERVING while it is full (new
    // sessions are refused then), SERVING again once it has room.
    disk->SetListener([s = server.get()](bool full) {
      for (grpc::Server* g : {s->server_.get(), s->health_server_.get()}) {
        if (g != nullptr && g->GetHealthCheckService() != nullptr) {
          g->GetHealthCheckService()->SetServingStatus(!full);
        }
      }
    });
    if (disk->Check() >= 0 && disk->full()) {
      ServerLog().warn("data disk {} starts full: new sessions are refused until it has room",
                       options.data_dir);
    }
    server->disk_thread_ = std::thread([s = server.get()] { s->WatchDisk(); });
  }
  server->address_ = absl::StrCat(HostOf(options.listen), ":", server->port_);
  server->replicas_->SetBoundAddress(server->address_);
  if (!server->replicas_->name().empty()) {
    std::string peers;
    for (const auto& p : server->replicas_->peers()) {
      absl::StrAppend(&peers, peers.empty() ? "" : ", ", p->replica, "=", p->address);
    }
    ServerLog().info("replica {} at {}; peers: {}", server->replicas_->name(),
                     server->replicas_->address(), peers.empty() ? "none" : peers);
  }
  ServerLog().info(
      "serving dynsolid.Sessions on {} ({}; max {} sessions, {} cells, {} MiB per session, {} "
      "bytes per message; {} stepping "
      "threads per session; streaming threads at nice +{}{}; builds at nice +{}; {})",
      server->address_, options.tls_cert_file.empty() ? "plaintext" : "TLS",
      options.max_sessions, options.max_cells,
      options.max_session_bytes < 0 ? std::string("unlimited")
                                    : std::to_string(options.max_session_bytes >> 20),
      options.max_message_bytes,
      SimThreads(options.sim_threads), options.stream_nice,
      options.stream_idle ? ", SCHED_IDLE" : "", options.loop.build_nice,
      options.data_dir.empty() ? std::string("in memory")
                               : absl::StrCat("data in ", options.data_dir, ", ",
                                              server->recovered_, " sessions recovered"));
  return server;
}

Server::~Server() { Shutdown(absl::Seconds(5)); }

void Server::WatchDisk() {
  absl::MutexLock lock(&disk_mu_);
  while (!disk_mu_.AwaitWithTimeout(absl::Condition(&disk_stop_),
                                    options_.disk_check_interval)) {
    disk_mu_.Unlock();
    options_.loop.disk->Check();
    disk_mu_.Lock();
  }
}

void Server::Shutdown(absl::Duration deadline) {
  {
    absl::MutexLock lock(&shutdown_mu_);
    if (shut_down_) return;
    shut_down_ = true;
  }
  ServerLog().info("shutting down ({} sessions open)", registry_.size());
  // 0. Health says NOT_SERVING at once (readiness probes fail: a load
  //    balancer stops sending new calls while the sessions drain).
  if (disk_thread_.joinable()) {
    {
      absl::MutexLock lock(&disk_mu_);
      disk_stop_ = true;
    }
    disk_thread_.join();
    options_.loop.disk->SetListener(nullptr);
  }
  for (grpc::Server* s : {server_.get(), health_server_.get()}) {
    if (s != nullptr && s->GetHealthCheckService() != nullptr) s->GetHealthCheckService()->Shutdown();
  }
  // 1. No new sessions; queued builds Finish with UNAVAILABLE.
  registry_.StopAccepting();
  builds_.Stop();
  // 2. Sessions stop: loops end, journals flush, streams finish.
  registry_.StopAll(absl::UnavailableError("the server is shutting down"));
  // 3. Running calls finish (or are cancelled at the deadline); a running
  //    build Finishes when it is done.
  server_->Shutdown(std::chrono::system_clock::now() +
                    absl::ToChronoMilliseconds(deadline));
  server_->Wait();
  if (health_server_ != nullptr) {
    health_server_->Shutdown(std::chrono::system_clock::now());
    health_server_->Wait();
  }
  // 4. No call can post work any more.
  builds_.Join();
  encoders_.Join();
  ServerLog().info("stopped");
}

}  // namespace dynsolid::server
