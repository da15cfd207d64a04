// gRPC channels to a dynsolid-server for the client side.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::client {

struct ChannelOptions {
  std::string address = "127.0.0.1:50051";
  // PEM root certificates: use TLS (empty: plaintext).
  std::string tls_root_certs;
  int max_message_bytes = 4 << 20;
};

// A channel with its own connection (a local subchannel pool): a new one
// connects at once, whatever state another channel to the same address is
// in.
std::shared_ptr<grpc::Channel> MakeChannel(const ChannelOptions& options);

// Makes new channels to where a session lives; the streams that reconnect
// call it for every new attempt. (gRPC's own reconnection of a channel whose
// server went away can stall for seconds after the server is back: its
// pick_first policy leaves the subchannel idle once the backoff elapses.)
//
// It starts at the address a client was given. With several replicas
// (docs/deploy.md) a session lives on one of them: Follow(Session) moves to
// the address CreateSession or GetSession returned, Follow(status) to the
// owner a redirect names. Copies share the route, so every stream and call
// of one session moves together; make one factory per session.
class ChannelFactory {
 public:
  ChannelFactory() = default;
  explicit ChannelFactory(ChannelOptions options);

  // A new channel to the current address.
  std::shared_ptr<grpc::Channel> operator()() const;
  std::string address() const;

  // Moves to `session.address` when it names one. Returns whether it moved.
  bool Follow(const Session& session) const;
  // If `status` is a redirect (FAILED_PRECONDITION with a SessionRedirect
  // in its details), moves to the owner's address and returns true.
  bool Follow(const grpc::Status& status) const;

 private:
  struct Route;
  std::shared_ptr<Route> route_;
};

// Redirects followed in a row before a call gives up (replicas that
// disagree about an owner would otherwise send a client round forever).
inline constexpr int kMaxRedirects = 4;

// The SessionRedirect a status carries, if any.
bool ParseRedirect(const grpc::Status& status, SessionRedirect* redirect);

// Receives progress messages (reconnects, script lines) when verbose.
using LogFn = std::function<void(const std::string&)>;

// A gRPC status as an Abseil one (same code); a non-empty `call` prefixes
// the message ("CreateSession: ...").
absl::Status ToAbslStatus(const grpc::Status& s, absl::string_view call = "");

// Stream statuses after which reconnecting cannot help, for any stream:
// refused tokens, bad or unknown requests, methods the server lacks.
// Callers add the codes final for their own stream.
bool IsFinalStreamStatus(grpc::StatusCode code);

inline ChannelFactory ChannelFactoryFor(ChannelOptions options) {
  return ChannelFactory(std::move(options));
}

}  // namespace dynsolid::client
