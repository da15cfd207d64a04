#include "server/replicas.h"

#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace dynsolid::server {
namespace {

bool ValidName(absl::string_view name) {
  if (name.empty() || name.size() > 63) return false;
  for (char c : name) {
    if (!(absl::ascii_islower(c) || absl::ascii_isdigit(c) || c == '-')) return false;
  }
  return name.front() != '-' && name.back() != '-';
}

bool ValidAddress(absl::string_view address) {
  const size_t colon = address.rfind(':');
  return colon != absl::string_view::npos && colon > 0 && colon + 1 < address.size();
}

}  // namespace

absl::StatusOr<std::unique_ptr<Replicas>> Replicas::Make(const ReplicaOptions& o) {
  std::unique_ptr<Replicas> r(new Replicas());
  if (!o.replica.empty() && !ValidName(o.replica)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "replica: \"", o.replica,
        "\" is not a replica name (1-63 of a-z, 0-9 and '-', not starting or ending with '-')"));
  }
  if (!o.advertise.empty() && !ValidAddress(o.advertise)) {
    return absl::InvalidArgumentError(
        absl::StrCat("advertise: \"", o.advertise, "\" is not HOST:PORT"));
  }
  r->name_ = o.replica;
  r->address_ = o.advertise;
  if (o.peers.empty()) return r;
  if (o.replica.empty()) {
    return absl::InvalidArgumentError("peers: needs --replica (this server's own name)");
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials =
      o.peer_roots_pem.empty()
          ? grpc::InsecureChannelCredentials()
          : grpc::SslCredentials(grpc::SslCredentialsOptions{o.peer_roots_pem, "", ""});
  std::vector<std::string> seen;
  for (absl::string_view entry : absl::StrSplit(o.peers, ',', absl::SkipWhitespace())) {
    entry = absl::StripAsciiWhitespace(entry);
    const std::pair<std::string, std::string> kv = absl::StrSplit(entry, absl::MaxSplits('=', 1));
    if (!ValidName(kv.first) || !ValidAddress(kv.second)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "peers: entry \"", entry, "\" is not NAME=HOST:PORT (NAME of a-z, 0-9 and '-')"));
    }
    for (const std::string& s : seen) {
      if (s == kv.first) {
        return absl::InvalidArgumentError(
            absl::StrCat("peers: replica \"", kv.first, "\" is listed twice"));
      }
    }
    seen.push_back(kv.first);
    if (kv.first == o.replica) {
      if (!o.advertise.empty() && kv.second != o.advertise) {
        return absl::InvalidArgumentError(absl::StrCat(
            "peers: this replica (\"", kv.first, "\") is listed at ", kv.second,
            " but --advertise says ", o.advertise));
      }
      if (o.advertise.empty()) r->address_ = kv.second;
      continue;
    }
    auto peer = std::make_unique<Peer>();
    peer->replica = kv.first;
    peer->address = kv.second;
    grpc::ChannelArguments args;
    // Each peer its own connection, whatever state other channels are in.
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    peer->stub = Sessions::NewStub(grpc::CreateCustomChannel(kv.second, credentials, args));
    r->peers_.push_back(std::move(peer));
  }
  return r;
}

std::string Replicas::address() const {
  absl::MutexLock lock(&mu_);
  return address_;
}

void Replicas::SetBoundAddress(const std::string& bound) {
  absl::MutexLock lock(&mu_);
  if (address_.empty()) address_ = bound;
}

absl::Status Replicas::Elsewhere(absl::string_view id) const {
  const size_t dot = id.find('.');
  if (dot == absl::string_view::npos) return absl::OkStatus();
  const absl::string_view owner = id.substr(0, dot);
  if (owner == name_) return absl::OkStatus();
  for (const auto& peer : peers_) {
    if (peer->replica == owner) return RedirectStatus(id, owner, peer->address);
  }
  return absl::NotFoundError(absl::StrCat(
      "session \"", id, "\" belongs to replica \"", owner, "\", which is not ",
      name_.empty() ? "this server (it runs alone: no --replica)"
                    : absl::StrCat("this replica (\"", name_, "\") or one of its peers")));
}

absl::Status RedirectStatus(absl::string_view id, absl::string_view owner,
                            absl::string_view address) {
  absl::Status s = absl::FailedPreconditionError(absl::StrCat(
      "session ", id, " lives on replica ", owner, " at ", address,
      ": call it there (dynsolid's client library and gateway follow this by themselves)"));
  SessionRedirect redirect;
  redirect.set_session_id(std::string(id));
  redirect.set_replica(std::string(owner));
  redirect.set_address(std::string(address));
  s.SetPayload(kRedirectTypeUrl, absl::Cord(redirect.SerializeAsString()));
  return s;
}

}  // namespace dynsolid::server
