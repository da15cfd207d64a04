#include "server/session_registry.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"

namespace dynsolid::server {

absl::StatusOr<std::shared_ptr<const SolidSession>> SessionRegistry::Create(
    const CreateSessionRequest& request, const std::function<bool()>& cancelled) {
  const auto is_cancelled = [&cancelled] { return cancelled != nullptr && cancelled(); };
  const absl::Status kCancelled =
      absl::CancelledError("the client cancelled the call; no session was opened");
  // Parsing and validation are cheap and stateless: a bad scene is reported
  // as such even when the server is full.
  absl::StatusOr<SceneRequest> scene = ResolveSceneRequest(request);
  if (!scene.ok()) return scene.status();

  {
    absl::MutexLock lock(&mu_);
    if (!accepting_) return absl::UnavailableError("the server is shutting down");
    if (is_cancelled()) return kCancelled;
    const int used = static_cast<int>(sessions_.size()) + pending_;
    if (used >= options_.max_sessions) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "the server already holds its maximum of ", options_.max_sessions,
          " sessions (", sessions_.size(), " open, ", pending_,
          " being created); close a session first"));
    }
    ++pending_;
  }

  // The expensive part, with no lock held.
  absl::StatusOr<BuiltSolid> solid = BuildSolid(*scene, options_.build);

  absl::MutexLock lock(&mu_);
  --pending_;
  if (!solid.ok()) return solid.status();
  if (!accepting_) return absl::UnavailableError("the server is shutting down");
  if (is_cancelled()) return kCancelled;
  std::string id;
  do {
    id = random_.Next(kSessionIdBits);
  } while (sessions_.contains(id));
  std::string token = random_.Next(kTokenBits);
  auto session = std::make_shared<const SolidSession>(id, std::move(token), scene->scene.name(),
                                                      absl::Now(), *std::move(solid));
  sessions_.emplace(std::move(id), Entry{next_serial_++, session});
  return session;
}

absl::StatusOr<std::shared_ptr<const SolidSession>> SessionRegistry::Find(
    absl::string_view id, absl::string_view token) const {
  if (id.empty()) return absl::InvalidArgumentError("SessionRef.id is empty");
  const auto it = sessions_.find(id);
  if (it == sessions_.end()) {
    return absl::NotFoundError(absl::StrCat("no open session with id \"", id, "\""));
  }
  if (token.empty()) {
    return absl::PermissionDeniedError(
        absl::StrCat("SessionRef.token is missing for session ", id));
  }
  if (!it->second.session->TokenMatches(token)) {
    return absl::PermissionDeniedError(
        absl::StrCat("SessionRef.token does not match session ", id));
  }
  return it->second.session;
}

absl::StatusOr<std::shared_ptr<const SolidSession>> SessionRegistry::Get(
    absl::string_view id, absl::string_view token) const {
  absl::ReaderMutexLock lock(&mu_);
  return Find(id, token);
}

absl::Status SessionRegistry::Close(absl::string_view id, absl::string_view token) {
  std::shared_ptr<const SolidSession> closed;  // freed after the lock is released
  absl::MutexLock lock(&mu_);
  absl::StatusOr<std::shared_ptr<const SolidSession>> found = Find(id, token);
  if (!found.ok()) return found.status();
  closed = *std::move(found);
  sessions_.erase(closed->id());
  return absl::OkStatus();
}

std::vector<std::shared_ptr<const SolidSession>> SessionRegistry::List() const {
  std::vector<const Entry*> entries;
  std::vector<std::shared_ptr<const SolidSession>> out;
  absl::ReaderMutexLock lock(&mu_);
  entries.reserve(sessions_.size());
  for (const auto& [id, entry] : sessions_) entries.push_back(&entry);
  std::sort(entries.begin(), entries.end(),
            [](const Entry* a, const Entry* b) { return a->serial < b->serial; });
  out.reserve(entries.size());
  for (const Entry* e : entries) out.push_back(e->session);
  return out;
}

int SessionRegistry::size() const {
  absl::ReaderMutexLock lock(&mu_);
  return static_cast<int>(sessions_.size());
}

void SessionRegistry::StopAccepting() {
  absl::MutexLock lock(&mu_);
  accepting_ = false;
}

}  // namespace dynsolid::server
