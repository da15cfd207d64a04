#include "server/session_registry.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "server/journal.h"
#include "server/log.h"
#include "server/persistence.h"

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
  // A session that could not journal its commands is not opened.
  if (!options_.data_dir.empty() && options_.loop.disk != nullptr) {
    if (absl::Status s = options_.loop.disk->CheckNewSession(); !s.ok()) return s;
  }

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
    id = options_.id_prefix + random_.Next(kSessionIdBits);
  } while (sessions_.contains(id));
  std::string token = random_.Next(kTokenBits);
  const absl::Time created = absl::Now();
  std::string dir;
  if (!options_.data_dir.empty()) {
    dir = SessionDir(options_.data_dir, id);
    persist::Manifest m;
    m.set_format(1);
    m.set_id(id);
    m.set_token(token);
    *m.mutable_scene() = scene->scene;
    m.set_base_dir(scene->base_dir);
    m.set_levels(scene->levels.value_or(-1));
    m.set_origin(scene->origin);
    m.set_created_unix_micros(absl::ToUnixMicros(created));
    m.set_start_paused(request.start_paused());
    if (absl::Status s = CreateSessionDir(dir, m); !s.ok()) {
      // No half-made directory is left for the next start to trip on.
      (void)RemoveDirTree(dir);
      if (absl::IsResourceExhausted(s) && options_.loop.disk != nullptr) {
        options_.loop.disk->ReportFull(s.message());
      }
      return s;
    }
  }
  CoreOptions core_options = options_.loop.core;
  core_options.can_save = !dir.empty();
  auto core = std::make_unique<SimCore>(solid->solid, core_options, request.start_paused(),
                                        scene->scene, MakeSolidFactory(*scene, options_.build));
  absl::Status error;
  std::shared_ptr<const SolidSession> session =
      OpenLocked(id, std::move(token), scene->scene.name(), created, *std::move(solid),
                 std::move(core), Recovered{}, dir, &error);
  if (session == nullptr) {
    if (!dir.empty()) (void)RemoveDirTree(dir);
    return error;
  }
  return session;
}

std::shared_ptr<const SolidSession> SessionRegistry::OpenLocked(
    std::string id, std::string token, std::string scene_name, absl::Time created,
    BuiltSolid built, std::unique_ptr<SimCore> core, Recovered recovered, std::string dir,
    absl::Status* error) {
  absl::StatusOr<std::unique_ptr<SessionLoop>> loop =
      SessionLoop::Start(id, std::move(core), options_.loop, dir, recovered);
  if (!loop.ok()) {
    *error = loop.status();
    return nullptr;
  }
  auto session = std::make_shared<const SolidSession>(
      id, std::move(token), std::move(scene_name), created, std::move(built.stats),
      std::move(built.discretization), *std::move(loop), std::move(dir));
  sessions_.emplace(std::move(id), Entry{next_serial_++, session});
  return session;
}

int SessionRegistry::RecoverAll() {
  if (options_.data_dir.empty()) return 0;
  int opened = 0;
  for (const std::string& dir : ListSessionDirs(options_.data_dir)) {
    CoreOptions core_options = options_.loop.core;
    core_options.can_save = true;
    absl::StatusOr<RecoveredSession> r = RecoverSession(dir, options_.build, core_options);
    if (!r.ok()) {
      SessionLog().error("cannot recover the session in {}: {}", dir, r.status().ToString());
      continue;
    }
    const persist::Manifest& m = r->manifest;
    absl::MutexLock lock(&mu_);
    if (sessions_.contains(m.id())) {
      ServerLog().error("{}: a session {} is already open", dir, m.id());
      continue;
    }
    absl::Status error;
    std::shared_ptr<const SolidSession> s =
        OpenLocked(m.id(), m.token(), m.scene().name(), absl::FromUnixMicros(m.created_unix_micros()),
                   std::move(r->built), std::move(r->core), r->recovered, dir, &error);
    if (s == nullptr) {
      ServerLog().error("cannot reopen the session in {}: {}", dir, error.ToString());
      continue;
    }
    SessionLog().info("session {} recovered: {}", m.id(), r->summary);
    ++opened;
  }
  return opened;
}

void SessionRegistry::StopAll(const absl::Status& status) {
  for (const auto& session : List()) session->loop().Stop(status);
}

absl::StatusOr<std::shared_ptr<const SolidSession>> SessionRegistry::Find(
    absl::string_view id, absl::string_view token) const {
  if (id.empty()) return absl::InvalidArgumentError("SessionRef.id is empty");
  const auto it = sessions_.find(id);
  if (it == sessions_.end()) {
    if (options_.elsewhere != nullptr) {
      if (absl::Status s = options_.elsewhere(id); !s.ok()) return s;
    }
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
  std::shared_ptr<const SolidSession> closed;  // stopped and freed after the lock is released
  {
    absl::MutexLock lock(&mu_);
    absl::StatusOr<std::shared_ptr<const SolidSession>> found = Find(id, token);
    if (!found.ok()) return found.status();
    closed = *std::move(found);
    sessions_.erase(closed->id());
  }
  closed->loop().Stop(absl::UnavailableError(absl::StrCat("session ", closed->id(), " was closed")));
  if (!closed->dir().empty()) {
    if (absl::Status s = RemoveDirTree(closed->dir()); !s.ok()) {
      ServerLog().warn("session {}: {}", closed->id(), s.ToString());
    }
  }
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

int SessionRegistry::creating() const {
  absl::ReaderMutexLock lock(&mu_);
  return pending_;
}

bool SessionRegistry::accepting() const {
  absl::ReaderMutexLock lock(&mu_);
  return accepting_;
}

void SessionRegistry::StopAccepting() {
  absl::MutexLock lock(&mu_);
  accepting_ = false;
}

}  // namespace dynsolid::server
