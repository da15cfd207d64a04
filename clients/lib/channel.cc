#include "clients/lib/channel.h"

#include "absl/strings/str_cat.h"

namespace dynsolid::client {

absl::Status ToAbslStatus(const grpc::Status& s, absl::string_view call) {
  if (s.ok()) return absl::OkStatus();
  const std::string message =
      call.empty() ? s.error_message() : absl::StrCat(call, ": ", s.error_message());
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), message);
}

std::shared_ptr<grpc::Channel> MakeChannel(const ChannelOptions& options) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  args.SetMaxReceiveMessageSize(options.max_message_bytes);
  args.SetMaxSendMessageSize(options.max_message_bytes);
  // Reconnect within a second when the server comes back (the default
  // backoff grows to two minutes). GRPC_ARG_MIN_RECONNECT_BACKOFF_MS stays
  // at its default: it is also the connect timeout, and a short one fails
  // handshakes on a loaded machine ("tcp handshaker shutdown").
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (options.tls_root_certs.empty()) {
    credentials = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = options.tls_root_certs;
    credentials = grpc::SslCredentials(ssl);
  }
  return grpc::CreateCustomChannel(options.address, credentials, args);
}

bool IsFinalStreamStatus(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::PERMISSION_DENIED:
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::UNAUTHENTICATED:
    case grpc::StatusCode::UNIMPLEMENTED:
      return true;
    default:
      return false;
  }
}

}  // namespace dynsolid::client
