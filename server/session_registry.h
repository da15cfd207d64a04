// The server's open sessions: creation under limits, lookup by id with
// token checks, listing and closing. Knows nothing of gRPC: every result is
// an absl::Status that the service maps at the edge.
//
// Thread-safe. The lock guards only the map and counters; a solid is built
// with no lock held (a slot is reserved first so concurrent creations never
// overshoot max_sessions).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"
#include "dynsolid/service.pb.h"
#include "server/session.h"
#include "server/session_loop.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"
#include "server/tokens.h"

namespace dynsolid::server {

struct RegistryOptions {
  // Open sessions plus creations in progress, at most.
  int max_sessions = 16;
  BuildLimits build;
  // How sessions run (watch rates, limits, answer caches, snapshots).
  LoopOptions loop;
  // With a data directory, every session persists under
  // data_dir/sessions/ID (persistence.h); empty: nothing is written.
  std::string data_dir;
  // New session ids start with this ("REPLICA."; replicas.h).
  std::string id_prefix;
  // Asked for an id that is not open here: a non-OK status (a redirect to
  // the owner replica) is returned instead of NotFound. May be empty.
  std::function<absl::Status(absl::string_view id)> elsewhere;
};

class SessionRegistry {
 public:
  explicit SessionRegistry(RegistryOptions options) : options_(std::move(options)) {}
  SessionRegistry(const SessionRegistry&) = delete;
  SessionRegistry& operator=(const SessionRegistry&) = delete;

  // Resolves the request's scene, reserves a slot, builds the solid (no lock
  // held; may take seconds) and opens a session with a fresh id and token.
  // Errors: those of ResolveSceneRequest and BuildSolid; ResourceExhausted
  // when max_sessions are open or being created; Unavailable after
  // StopAccepting; Cancelled when `cancelled` (if given) returns true before
  // the build starts or once it is done: a solid nobody waits for is never
  // opened. A failed creation changes nothing.
  absl::StatusOr<std::shared_ptr<const SolidSession>> Create(
      const CreateSessionRequest& request, const std::function<bool()>& cancelled = nullptr);

  // The session `id` if `token` is its token. InvalidArgument for an empty
  // id, NotFound for an unknown one, PermissionDenied for a missing or wrong
  // token.
  absl::StatusOr<std::shared_ptr<const SolidSession>> Get(absl::string_view id,
                                                          absl::string_view token) const;

  // Removes the session (same errors as Get). Holders of the session keep
  // it alive until they let go.
  absl::Status Close(absl::string_view id, absl::string_view token);

  // Every open session, oldest first.
  std::vector<std::shared_ptr<const SolidSession>> List() const;

  // Restores every session found under options.data_dir (persistence.h),
  // in directory order. A session that cannot be recovered is logged and
  // left on disk untouched; the others open. Returns how many opened.
  int RecoverAll();

  // Stops every session's loop with `status` (server shutdown): streams
  // finish, journals are flushed, a last snapshot is written.
  void StopAll(const absl::Status& status);

  int size() const;
  // Creations in progress (slots reserved, solids being built).
  int creating() const;
  bool accepting() const;

  // From now on Create fails with Unavailable (server shutdown). Sessions
  // being built finish, but are not opened.
  void StopAccepting();

 private:
  absl::StatusOr<std::shared_ptr<const SolidSession>> Find(absl::string_view id,
                                                           absl::string_view token) const
      ABSL_SHARED_LOCKS_REQUIRED(mu_);

  struct Entry {
    uint64_t serial;  // creation order
    std::shared_ptr<const SolidSession> session;
  };

  // Opens a built solid as session `id` (lock held).
  std::shared_ptr<const SolidSession> OpenLocked(std::string id, std::string token,
                                                 std::string scene_name, absl::Time created,
                                                 BuiltSolid built, std::unique_ptr<SimCore> core,
                                                 Recovered recovered, std::string dir,
                                                 absl::Status* error)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const RegistryOptions options_;

 public:
  const RegistryOptions& options() const { return options_; }
  mutable absl::Mutex mu_;
  absl::flat_hash_map<std::string, Entry> sessions_ ABSL_GUARDED_BY(mu_);
  int pending_ ABSL_GUARDED_BY(mu_) = 0;  // creations holding a reserved slot
  uint64_t next_serial_ ABSL_GUARDED_BY(mu_) = 0;
  bool accepting_ ABSL_GUARDED_BY(mu_) = true;
  RandomHex random_ ABSL_GUARDED_BY(mu_);
};

}  // namespace dynsolid::server
