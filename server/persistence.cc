#include "server/persistence.h"

#include <dirent.h>

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "server/journal.h"

namespace dynsolid::server {

std::string SessionDir(const std::string& data_dir, const std::string& id) {
  return absl::StrCat(data_dir, "/sessions/", id);
}

absl::Status CreateSessionDir(const std::string& dir, const persist::Manifest& manifest) {
  if (absl::Status s = MakeDirs(dir); !s.ok()) return s;
  return WriteFileAtomically(dir, "manifest.binpb", manifest.SerializeAsString(), 0600);
}

std::vector<std::string> ListSessionDirs(const std::string& data_dir) {
  std::vector<std::string> out;
  const std::string root = absl::StrCat(data_dir, "/sessions");
  DIR* d = ::opendir(root.c_str());
  if (d == nullptr) return out;
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name == "." || name == "..") continue;
    out.push_back(absl::StrCat(root, "/", name));
  }
  ::closedir(d);
  std::sort(out.begin(), out.end());
  return out;
}

SceneRequest SceneRequestOf(const persist::Manifest& m) {
  SceneRequest r;
  r.scene = m.scene();
  r.base_dir = m.base_dir();
  r.origin = m.origin();
  if (m.levels() >= 0) r.levels = m.levels();
  return r;
}

absl::StatusOr<RecoveredSession> RecoverSession(const std::string& dir, const BuildLimits& limits,
                                                const CoreOptions& core_options) {
  RecoveredSession out;
  absl::StatusOr<std::string> manifest = ReadWholeFile(absl::StrCat(dir, "/manifest.binpb"));
  if (!manifest.ok()) return manifest.status();
  if (!out.manifest.ParseFromString(*manifest) || out.manifest.format() != 1) {
    return absl::DataLossError(absl::StrCat(dir, "/manifest.binpb is not a format-1 manifest"));
  }
  absl::StatusOr<BuiltSolid> built = BuildSolid(SceneRequestOf(out.manifest), limits);
  if (!built.ok()) return built.status();
  out.built = *std::move(built);
  const SceneRequest request = SceneRequestOf(out.manifest);
  auto make_core = [&] {
    return std::make_unique<SimCore>(out.built.solid, core_options, out.manifest.start_paused(),
                                     request.scene, MakeSolidFactory(request, limits));
  };
  out.core = make_core();

  // The snapshot, if there is a whole one.
  uint64_t offset = 0;
  absl::StatusOr<JournalContents> snap = ReadJournal(absl::StrCat(dir, "/snapshot.binpb"), 0);
  if (snap.ok() && snap->records.size() == 1) {
    persist::Snapshot snapshot;
    absl::Status s = snapshot.ParseFromString(snap->records[0])
                         ? out.core->RestoreFrom(snapshot)
                         : absl::DataLossError("snapshot.binpb does not parse");
    if (s.ok()) {
      offset = snapshot.journal_offset();
      out.recovered.last_snapshot_step = snapshot.step();
      absl::StrAppend(&out.summary, "snapshot at step ", snapshot.step(), "; ");
    } else {
      // Start over from step 0 and the whole journal.
      absl::StrAppend(&out.summary, "snapshot unusable (", s.message(), "), replaying all; ");
      absl::StatusOr<BuiltSolid> fresh = BuildSolid(SceneRequestOf(out.manifest), limits);
      if (!fresh.ok()) return fresh.status();
      out.built = *std::move(fresh);
      out.core = make_core();
    }
  }
  absl::StatusOr<JournalContents> journal = ReadJournal(absl::StrCat(dir, "/journal"), offset);
  if (!journal.ok()) return journal.status();
  for (const std::string& payload : journal->records) {
    persist::JournalRecord record;
    if (!record.ParseFromString(payload)) {
      return absl::DataLossError(absl::StrCat(dir, "/journal: a record with a valid CRC does not parse"));
    }
    if (absl::Status s = out.core->Replay(record); !s.ok()) {
      return absl::DataLossError(absl::StrCat(dir, "/journal: ", s.message()));
    }
  }
  out.recovered.journal_end = journal->valid_end;
  out.recovered.journal_records = static_cast<int64_t>(journal->records.size());
  absl::StrAppend(&out.summary, journal->records.size(), " journal records replayed to step ",
                  out.core->steps());
  if (!journal->tail_problem.empty()) {
    absl::StrAppend(&out.summary, "; dropped ", journal->file_bytes - journal->valid_end,
                    " bytes of unacknowledged tail (", journal->tail_problem, ")");
  }
  return out;
}

}  // namespace dynsolid::server
