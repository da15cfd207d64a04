#include "server/replay.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "dynsolid/journal.pb.h"
#include "server/journal.h"
#include "server/persistence.h"
#include "solver/common/status_macros.h"
#include "solver/export/design_export.h"
#include "solver/io/gltf_writer.h"

namespace dynsolid::server {
namespace {

std::string Stem(const std::string& name) {
  std::string out;
  for (char c : name) out.push_back(std::isalnum(static_cast<unsigned char>(c)) || c == '-' ? c : '_');
  return out.empty() ? "session" : out.substr(0, 64);
}

// The options that are checked before the session is read.
absl::Status CheckOptions(const ReplayOptions& o) {
  if (!(o.fps > 0) || !std::isfinite(o.fps)) {
    return absl::InvalidArgumentError(absl::StrCat("--fps: ", o.fps, " is not a positive number"));
  }
  if (!std::isfinite(o.from) || o.from < 0 || !std::isfinite(o.to)) {
    return absl::InvalidArgumentError(absl::StrCat("--from ", o.from, " --to ", o.to,
                                                   ": times are finite seconds, --from >= 0"));
  }
  if (o.level < -1 || o.level > 6) {
    return absl::InvalidArgumentError(absl::StrCat("--level: ", o.level, " is outside 0-6"));
  }
  if (!o.pvd && !o.obj && !o.glb) return absl::InvalidArgumentError("--format: no format to write");
  return absl::OkStatus();
}

// What the replay reads of a session directory.
struct SessionFiles {
  persist::Manifest manifest;
  std::vector<persist::JournalRecord> records;
  int64_t snapshot_step = 0;
};

absl::StatusOr<SessionFiles> ReadSessionFiles(const std::string& dir) {
  SessionFiles files;
  // The session as it was created, and its whole journal.
  absl::StatusOr<std::string> manifest_bytes = ReadWholeFile(dir + "/manifest.binpb");
  if (!manifest_bytes.ok()) {
    return absl::NotFoundError(absl::StrCat(dir, "/manifest.binpb: not a session directory (",
                                            manifest_bytes.status().message(), ")"));
  }
  persist::Manifest& manifest = files.manifest;
  if (!manifest.ParseFromString(*manifest_bytes) || manifest.format() != 1) {
    return absl::DataLossError(absl::StrCat(dir, "/manifest.binpb is not a format-1 manifest"));
  }
  ASSIGN_OR_RETURN(JournalContents journal, ReadJournal(dir + "/journal", 0));
  std::vector<persist::JournalRecord>& records = files.records;
  records.resize(journal.records.size());
  for (size_t i = 0; i < records.size(); ++i) {
    if (!records[i].ParseFromString(journal.records[i])) {
      return absl::DataLossError(absl::StrCat(dir, "/journal: record ", i, " does not parse"));
    }
  }
  // Steps after the last record are written down only by a snapshot, or by
  // the record itself when it left the session paused with a Step count
  // (known once the replay reaches it).
  if (absl::StatusOr<JournalContents> snap = ReadJournal(dir + "/snapshot.binpb", 0);
      snap.ok() && snap->records.size() == 1) {
    persist::Snapshot snapshot;
    if (snapshot.ParseFromString(snap->records[0])) files.snapshot_step = snapshot.step();
  }
  return files;
}

// The animation's files: each frame's .vtu and .obj as the replay reaches
// it (with its line in the .pvd), and at the end the .glb (every frame's
// surface, as morph targets of the first) and the .pvd. What it writes is
// listed in the report's files.
class FrameFiles {
 public:
  FrameFiles(const ReplayOptions& o, int level, std::string stem, ReplayReport& rep)
      : o_(o), level_(level), stem_(std::move(stem)), rep_(rep) {}

  // The frame `index`: the solid as it is now.
  absl::Status Write(const solid::Solid& s, int index);
  // The .glb and the .pvd.
  absl::Status Finish();

 private:
  const ReplayOptions& o_;
  const int level_;
  const std::string stem_;
  ReplayReport& rep_;
  std::optional<mesh::BoundarySurface> glb_first_;  // --format glb: the first frame
  std::vector<Points> glb_frames_;                  // and the later ones' positions
  std::string pvd_ =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n";
};

absl::Status FrameFiles::Write(const solid::Solid& s, int index) {
  exporter::DesignInput in{&s.discretization(), s.control_positions(),
                           s.discretization().control().positions()};
  // The volume's material cell data, as the live export gives it.
  std::optional<exporter::MaterialFields> materials;
  if (o_.pvd) {
    absl::StatusOr<exporter::MaterialFields> m = exporter::MaterialFieldsOf(s.discretization(), s.SaveDesign());
    if (m.ok()) {
      materials = *std::move(m);
      in.materials = &*materials;
    }
  }
  const std::string base = absl::StrFormat("%s_%04d", stem_, index);
  for (const bool volume : {true, false}) {
    if (volume ? !o_.pvd : !o_.obj) continue;
    exporter::ExportOptions eo;
    eo.format = volume ? exporter::Format::kVtu : exporter::Format::kObj;
    eo.level = level_;
    absl::StatusOr<exporter::Exported> made = exporter::ExportDesign(in, eo);
    if (!made.ok()) {
      return absl::Status(made.status().code(), absl::StrCat("--", made.status().message()));
    }
    const std::string file = absl::StrCat(base, volume ? ".vtu" : ".obj");
    RETURN_IF_ERROR(WriteFileAtomically(o_.out_dir, file, made->bytes, 0644));
    rep_.files.push_back(file);
    if (volume) {
      absl::StrAppend(&pvd_, "    <DataSet timestep=\"", absl::StrFormat("%.17g", s.time()),
                      "\" part=\"0\" file=\"", file, "\"/>\n");
    }
  }
  if (o_.glb) {
    exporter::ExportOptions eo;
    eo.format = exporter::Format::kGlb;
    eo.level = level_;
    absl::StatusOr<mesh::BoundarySurface> surface = exporter::DesignSurface(in, eo);
    if (!surface.ok()) {
      return absl::Status(surface.status().code(), absl::StrCat("--", surface.status().message()));
    }
    if (glb_first_.has_value()) {
      if (surface->faces.offsets != glb_first_->faces.offsets ||
          surface->faces.items != glb_first_->faces.items) {
        return absl::InvalidArgumentError(absl::StrCat(
            "--format glb: the surface changed at step ", s.steps(), " (a topology edit); a glTF "
            "animation needs one surface: start after it (--from) or use pvd or obj"));
      }
      glb_frames_.push_back(std::move(surface->positions));
    } else {
      glb_first_ = *std::move(surface);
    }
  }
  rep_.frame_steps.push_back(s.steps());
  rep_.frame_times.push_back(s.time());
  return absl::OkStatus();
}

absl::Status FrameFiles::Finish() {
  if (o_.glb && glb_first_.has_value()) {
    io::GlbOptions g;
    g.generator = "dynsolid-replay";
    g.morph_frames = std::move(glb_frames_);
    g.morph_times = rep_.frame_times;
    std::string bytes;
    RETURN_IF_ERROR(io::GlbBytes(*glb_first_, g, &bytes));
    const std::string file = stem_ + ".glb";
    RETURN_IF_ERROR(WriteFileAtomically(o_.out_dir, file, bytes, 0644));
    rep_.files.push_back(file);
  }
  if (o_.pvd) {
    absl::StrAppend(&pvd_, "  </Collection>\n</VTKFile>\n");
    const std::string file = stem_ + ".pvd";
    RETURN_IF_ERROR(WriteFileAtomically(o_.out_dir, file, pvd_, 0644));
    rep_.files.push_back(file);
  }
  return absl::OkStatus();
}

// Step by step: at each step boundary its records are applied (as the
// live loop did, in journal order), then a frame is written if one is
// due, then the session steps if it was running. The end is known once
// the last record is applied: where a Step count pauses the session, or
// the last record's step (or the snapshot's, when later) for a session
// that was running. `h` is the session's step.
absl::Status ReplayJournal(const std::string& dir, const ReplayOptions& o,
                           const SessionFiles& files, double h, SimCore& core,
                           FrameFiles& frames, ReplayReport& rep) {
  const std::vector<persist::JournalRecord>& records = files.records;
  const int64_t snapshot_step = files.snapshot_step;
  size_t next = 0;
  int64_t frame = 0;
  std::optional<int64_t> end;
  double to = o.to;
  for (;;) {
    const int64_t step = core.steps();
    while (next < records.size() && records[next].step() == step) {
      if (absl::Status s = core.Replay(records[next]); !s.ok()) {
        return absl::DataLossError(absl::StrCat(dir, "/journal: ", s.message()));
      }
      ++next;
    }
    if (!end.has_value() && next == records.size()) {
      const int64_t last = records.empty() ? 0 : records.back().step();
      end = !core.WantsStep() ? step
            : core.paused()   ? step + core.steps_remaining()
                              : std::max({last, snapshot_step, step});
      rep.end_step = *end;
      rep.end_time = static_cast<double>(*end) * h;
      if (to < 0) to = rep.end_time;
      if (o.from > to || to > rep.end_time * (1 + 1e-12) + 1e-12) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "--from %g --to %g: the journal covers [0, %g] s (steps 0-%d, %d records)", o.from, to,
            rep.end_time, *end, records.size()));
      }
    }
    // The frames due here: those whose time is nearest this step.
    bool past = false;
    for (;; ++frame) {
      const double t = o.from + static_cast<double>(frame) / o.fps;
      if (to >= 0 && t > to * (1 + 1e-12) + 1e-12) {
        past = true;
        break;
      }
      const int64_t at = std::llround(t / h);
      if (at > step) break;
      if (at == step && (rep.frame_steps.empty() || rep.frame_steps.back() < step)) {
        if (rep.frame_steps.size() >= 100000) {
          return absl::InvalidArgumentError("--fps, --from, --to: more than 100000 frames");
        }
        RETURN_IF_ERROR(frames.Write(core.solid(), static_cast<int>(rep.frame_steps.size())));
      }
    }
    if (past || (end.has_value() && step >= *end)) break;
    if (!core.WantsStep()) {
      return absl::DataLossError(absl::StrCat(dir, ": the session is paused at step ", step,
                                              " and the journal's next record is at step ",
                                              records[next].step()));
    }
    (void)core.StepOnce();  // a failed step is part of the history (it pauses)
  }
  if (!end.has_value()) {
    // The range ended before the last record: the end is at least there.
    rep.end_step = std::max({records.back().step(), snapshot_step, core.steps()});
    rep.end_time = static_cast<double>(rep.end_step) * h;
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<ReplayReport> ReplayAnimation(const std::string& dir, const ReplayOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  RETURN_IF_ERROR(CheckOptions(o));
  ASSIGN_OR_RETURN(SessionFiles files, ReadSessionFiles(dir));
  const SceneRequest request = SceneRequestOf(files.manifest);
  ASSIGN_OR_RETURN(BuiltSolid built, BuildSolid(request, o.limits));
  CoreOptions core_options = o.core;
  core_options.can_save = true;
  SimCore core(built.solid, core_options, files.manifest.start_paused(), request.scene,
               MakeSolidFactory(request, o.limits));
  const double h = core.solid().time_step();
  ReplayReport rep;
  rep.journal_records = static_cast<int64_t>(files.records.size());
  if (o.fps * h > 1 + 1e-9) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "--fps %g: more than one frame per step (the session steps %g s, at most %g fps)", o.fps, h,
        1 / h));
  }
  if (o.to >= 0 && o.from > o.to) {
    return absl::InvalidArgumentError(absl::StrFormat("--from %g is after --to %g", o.from, o.to));
  }
  const int level = o.level >= 0 ? o.level : core.solid().discretization().hierarchy.levels;
  const std::string stem = o.name.empty() ? Stem(request.scene.name())
                                          : Stem(o.name);
  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat("--out ", o.out_dir, ": ", ec.message()));

  // Files written so far: removed again if the replay fails.
  struct Cleanup {
    const std::string& dir;
    std::vector<std::string>* files;
    bool keep = false;
    ~Cleanup() {
      if (keep) return;
      for (const std::string& f : *files) std::filesystem::remove(dir + "/" + f);
    }
  } cleanup{o.out_dir, &rep.files};
  FrameFiles frames(o, level, stem, rep);
  RETURN_IF_ERROR(ReplayJournal(dir, o, files, h, core, frames, rep));
  RETURN_IF_ERROR(frames.Finish());
  rep.frames = static_cast<int>(rep.frame_steps.size());
  cleanup.keep = true;
  rep.milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return rep;
}

}  // namespace dynsolid::server
