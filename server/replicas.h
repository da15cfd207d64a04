// The replica set a server belongs to (docs/deploy.md "How sessions are
// placed and found"): its own name and client address, its peers, and the
// rules that follow from session ids naming their owner ("REPLICA.HEX"):
// which ids are this server's, the redirect for the others, and where a
// new session goes (the least loaded replica that answers). No shared
// database: a session's id is enough to find it.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::server {

struct ReplicaOptions {
  // This replica's name ([a-z0-9-], 1-63 characters, e.g. a StatefulSet
  // pod's name). Empty: the server runs alone (bare session ids).
  std::string replica;
  // HOST:PORT clients use to reach this replica (empty: the bound address).
  std::string advertise;
  // Every replica of the set as NAME=HOST:PORT, comma-separated; this
  // replica's own entry may be listed (it is skipped). Needs `replica`.
  std::string peers;
  // PEM roots for calls to peers (TLS); empty: plaintext.
  std::string peer_roots_pem;
};

// The metadata key CreateSession carries when a replica forwards it to the
// peer it chose: build here, do not place again.
inline constexpr char kPlacedHereKey[] = "dynsolid-placed-by";

// The absl payload (and Any) type URL of a SessionRedirect.
inline constexpr char kRedirectTypeUrl[] = "type.googleapis.com/dynsolid.SessionRedirect";

class Replicas {
 public:
  struct Peer {
    std::string replica;
    std::string address;
    std::unique_ptr<Sessions::Stub> stub;
    // Creations forwarded to this peer and not yet answered: counted as its
    // load, so concurrent creations spread instead of piling on one peer.
    std::atomic<int> forwarding{0};
  };

  // Checks and parses the options (InvalidArgument naming the flag and the
  // entry). Peers get channels at once; they connect on first use.
  static absl::StatusOr<std::unique_ptr<Replicas>> Make(const ReplicaOptions& options);

  const std::string& name() const { return name_; }
  std::string address() const;
  // Sets the advertised address to the bound one when --advertise is empty.
  void SetBoundAddress(const std::string& bound);
  bool has_peers() const { return !peers_.empty(); }
  std::vector<std::unique_ptr<Peer>>& peers() { return peers_; }
  const std::vector<std::unique_ptr<Peer>>& peers() const { return peers_; }

  // What a new session id starts with: "NAME." or "" when alone.
  std::string IdPrefix() const { return name_.empty() ? "" : name_ + "."; }

  // For an id not open here: the redirect to its owner when the id names a
  // peer (FailedPrecondition with a SessionRedirect payload), NotFound
  // naming the replica when it names one this server does not know, OK
  // when it names this replica or none (the caller reports it unknown).
  absl::Status Elsewhere(absl::string_view id) const;

 private:
  Replicas() = default;
  std::string name_;
  mutable absl::Mutex mu_;
  std::string address_ ABSL_GUARDED_BY(mu_);
  std::vector<std::unique_ptr<Peer>> peers_;
};

// The redirect status for session `id` owned by `owner` at `address`.
absl::Status RedirectStatus(absl::string_view id, absl::string_view owner,
                            absl::string_view address);

}  // namespace dynsolid::server
