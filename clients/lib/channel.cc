#include "clients/lib/channel.h"

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"

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

struct ChannelFactory::Route {
  ChannelOptions first;
  mutable absl::Mutex mu;
  std::string address ABSL_GUARDED_BY(mu);
};

ChannelFactory::ChannelFactory(ChannelOptions options) : route_(std::make_shared<Route>()) {
  route_->address = options.address;
  route_->first = std::move(options);
}

std::shared_ptr<grpc::Channel> ChannelFactory::operator()() const {
  ChannelOptions o = route_->first;
  o.address = address();
  return MakeChannel(o);
}

std::string ChannelFactory::address() const {
  absl::MutexLock lock(&route_->mu);
  return route_->address;
}

bool ChannelFactory::Follow(const Session& session) const {
  if (session.address().empty()) return false;
  absl::MutexLock lock(&route_->mu);
  if (route_->address == session.address()) return false;
  route_->address = session.address();
  return true;
}

bool ChannelFactory::Follow(const grpc::Status& status) const {
  SessionRedirect redirect;
  if (!ParseRedirect(status, &redirect)) return false;
  absl::MutexLock lock(&route_->mu);
  route_->address = redirect.address();
  return true;
}

bool ParseRedirect(const grpc::Status& status, SessionRedirect* redirect) {
  if (status.error_code() != grpc::StatusCode::FAILED_PRECONDITION ||
      status.error_details().empty()) {
    return false;
  }
  RpcStatus details;
  if (!details.ParseFromString(status.error_details())) return false;
  for (const google::protobuf::Any& any : details.details()) {
    if (any.Is<SessionRedirect>() && any.UnpackTo(redirect) && !redirect->address().empty()) {
      return true;
    }
  }
  return false;
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
