// One open session: a solid built from a scene, reachable by its id and
// authorized by its token.
//
// In this slice a session is immutable once created, so readers share it
// through shared_ptr<const SolidSession> without locks. The sim loop that
// arrives later adds its mutable state (commands, frames) behind its own
// synchronization; the built discretization stays read-only and shared.
#pragma once

#include <memory>
#include <string>
#include <utility>

#include "absl/strings/string_view.h"
#include "absl/time/time.h"
#include "dynsolid/service.pb.h"
#include "server/solid_builder.h"
#include "server/tokens.h"

namespace dynsolid::server {

class SolidSession {
 public:
  SolidSession(std::string id, std::string token, std::string scene_name, absl::Time created,
               BuiltSolid solid)
      : id_(std::move(id)),
        token_(std::move(token)),
        scene_name_(std::move(scene_name)),
        created_(created),
        solid_(std::move(solid)) {}
  SolidSession(const SolidSession&) = delete;
  SolidSession& operator=(const SolidSession&) = delete;

  const std::string& id() const { return id_; }
  const std::string& scene_name() const { return scene_name_; }
  absl::Time created() const { return created_; }
  const SolidStats& stats() const { return solid_.stats; }
  const std::shared_ptr<const scene::Discretization>& discretization() const {
    return solid_.discretization;
  }

  // Whether `token` is this session's token (constant-time comparison).
  bool TokenMatches(absl::string_view token) const { return TokensEqual(token, token_); }

  // The session as the service returns it, token included: only for a
  // caller that created the session or presented its token.
  Session ToProto() const;
  // The session's list entry (no token).
  ListSessionsResponse::Entry ToListEntry() const;

 private:
  const std::string id_;
  const std::string token_;
  const std::string scene_name_;
  const absl::Time created_;
  const BuiltSolid solid_;
};

}  // namespace dynsolid::server
