// One open session: a solid built from a scene, stepped by its own
// simulation thread (SessionLoop), reachable by its id and authorized by
// its token.
//
// The session's identity and discretization statistics are immutable, so
// readers share it through shared_ptr<const SolidSession> without locks;
// everything that changes lives in the SessionLoop, which synchronizes
// itself (its methods are safe to call from any thread).
#pragma once

#include <memory>
#include <string>
#include <utility>

#include "absl/strings/string_view.h"
#include "absl/time/time.h"
#include "dynsolid/service.pb.h"
#include "server/session_loop.h"
#include "server/solid_builder.h"
#include "server/tokens.h"

namespace dynsolid::server {

class SolidSession {
 public:
  // `dir` is the session's data directory ("" without --data-dir).
  SolidSession(std::string id, std::string token, std::string scene_name, absl::Time created,
               SolidStats stats, std::shared_ptr<const scene::Discretization> discretization,
               std::unique_ptr<SessionLoop> loop, std::string dir)
      : id_(std::move(id)),
        token_(std::move(token)),
        scene_name_(std::move(scene_name)),
        created_(created),
        stats_(std::move(stats)),
        discretization_(std::move(discretization)),
        loop_(std::move(loop)),
        dir_(std::move(dir)) {}
  SolidSession(const SolidSession&) = delete;
  SolidSession& operator=(const SolidSession&) = delete;

  const std::string& id() const { return id_; }
  const std::string& scene_name() const { return scene_name_; }
  absl::Time created() const { return created_; }
  const SolidStats& stats() const { return stats_; }
  const std::shared_ptr<const scene::Discretization>& discretization() const {
    return discretization_;
  }
  // The simulation loop (internally synchronized).
  SessionLoop& loop() const { return *loop_; }
  const std::string& dir() const { return dir_; }

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
  const SolidStats stats_;
  const std::shared_ptr<const scene::Discretization> discretization_;
  const std::unique_ptr<SessionLoop> loop_;
  const std::string dir_;
};

}  // namespace dynsolid::server
