// A session's data directory with --data-dir: DATA_DIR/sessions/ID/
//   manifest.binpb  persist::Manifest: id, token, resolved scene (mode 0600;
//                   the token is stored as is, protected by the file mode
//                   and the 0700 directories: a restarted server must
//                   accept the same token, and a hash would serve equally
//                   well; the token is never logged)
//   journal         framed persist::JournalRecords (journal.h), appended and
//                   fdatasync'd before each reply is released
//   snapshot.binpb  one framed persist::Snapshot (solid state, loop state,
//                   answer caches, journal offset), replaced atomically
// Recovery rebuilds the solid from the manifest's scene, restores the
// snapshot (if any and valid), replays the journal from the snapshot's
// offset through the same SimCore code as the live loop (which checks each
// record's outcome again), and truncates a torn tail.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/journal.pb.h"
#include "server/session_loop.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"

namespace dynsolid::server {

std::string SessionDir(const std::string& data_dir, const std::string& id);

// Creates the session's directory and writes its manifest durably.
absl::Status CreateSessionDir(const std::string& dir, const persist::Manifest& manifest);

// The session directories under data_dir (sorted by name).
std::vector<std::string> ListSessionDirs(const std::string& data_dir);

struct RecoveredSession {
  persist::Manifest manifest;
  BuiltSolid built;
  std::unique_ptr<SimCore> core;
  Recovered recovered;
  // What recovery did, for the log.
  std::string summary;
};

// Rebuilds a session from its directory (see above). DataLoss when the
// journal does not replay to the same outcomes; the directory is left as is
// on error.
absl::StatusOr<RecoveredSession> RecoverSession(const std::string& dir, const BuildLimits& limits,
                                                const CoreOptions& core_options);

// The SceneRequest a manifest stores.
SceneRequest SceneRequestOf(const persist::Manifest& manifest);

}  // namespace dynsolid::server
