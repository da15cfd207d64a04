// gRPC channels to a dynsolid-server for the client side.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

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

// Makes a new channel; the streams that reconnect call it for every new
// attempt. (gRPC's own reconnection of a channel whose server went away
// can stall for seconds after the server is back: its pick_first policy
// leaves the subchannel idle once the backoff elapses.)
using ChannelFactory = std::function<std::shared_ptr<grpc::Channel>()>;

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
  return [options] { return MakeChannel(options); };
}

}  // namespace dynsolid::client
