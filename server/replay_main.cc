// dynsolid-replay: an animation of a session from its journal (replay.h).
//
//   dynsolid-replay --session DATA_DIR/sessions/ID --out DIR
//                   [--from 0] [--to END] [--fps 30] [--level L]
//                   [--format pvd,obj,glb] [--name STEM]
//                   [--undo_bytes N] [--answer_cache N]
//
// Prints one JSON line: the frames, their steps and times, the files. Exit
// codes: 0 written; 2 bad flags or a range outside the journal (nothing
// written); 1 a journal that does not replay or a file that cannot be
// written.
#include <cstdint>
#include <iostream>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "cmdline/cmdline.h"
#include "server/replay.h"

ABSL_FLAG(std::string, session, "", "The session's directory: DATA_DIR/sessions/ID");
ABSL_FLAG(std::string, out, "", "Directory for the frames (created if missing)");
ABSL_FLAG(double, from, 0, "First frame's time, seconds of session time");
ABSL_FLAG(double, to, -1, "Last frame's time at most, seconds; -1: the journal's end");
ABSL_FLAG(double, fps, 30, "Frames per second of session time (at most one per step)");
ABSL_FLAG(int, level, -1, "Subdivision levels of the frames, 0-6; -1: the session's");
ABSL_FLAG(std::string, format, "pvd",
          "Comma separated: pvd (a VTU per frame and a .pvd index for ParaView), obj (an OBJ "
          "per frame), glb (one glTF file, a morph target per frame)");
ABSL_FLAG(std::string, name, "", "Stem of the file names; empty: the scene's name");
ABSL_FLAG(int64_t, undo_bytes, int64_t{256} << 20,
          "The server's --undo_bytes when it ran the session (part of its determinism)");
ABSL_FLAG(int, answer_cache, 256, "The server's --answer_cache when it ran the session");
ABSL_FLAG(int64_t, max_cells, 1'000'000, "The server's --max_cells");

int main(int argc, char** argv) {
  dynsolid::cmdline::ParseCommandLine(
      argc, argv,
      "dynsolid-replay --session DATA_DIR/sessions/ID --out DIR [--from S] [--to S] [--fps F] "
      "[--level L] [--format pvd,obj]",
      __FILE__);
  dynsolid::server::ReplayOptions o;
  const std::string session = absl::GetFlag(FLAGS_session);
  o.out_dir = absl::GetFlag(FLAGS_out);
  if (session.empty() || o.out_dir.empty()) {
    std::cerr << "dynsolid-replay: --session and --out are required\n";
    return 2;
  }
  o.from = absl::GetFlag(FLAGS_from);
  o.to = absl::GetFlag(FLAGS_to);
  o.fps = absl::GetFlag(FLAGS_fps);
  o.level = absl::GetFlag(FLAGS_level);
  o.name = absl::GetFlag(FLAGS_name);
  o.core.undo_bytes = absl::GetFlag(FLAGS_undo_bytes);
  o.core.answer_cache = absl::GetFlag(FLAGS_answer_cache);
  o.limits.max_cells = absl::GetFlag(FLAGS_max_cells);
  o.limits.sim_threads = 1;
  o.pvd = o.obj = false;
  for (absl::string_view f : absl::StrSplit(absl::GetFlag(FLAGS_format), ',', absl::SkipEmpty())) {
    if (f == "pvd" || f == "vtu") {
      o.pvd = true;
    } else if (f == "obj") {
      o.obj = true;
    } else if (f == "glb") {
      o.glb = true;
    } else {
      std::cerr << "dynsolid-replay: --format: unknown format \"" << f << "\" (pvd, obj, glb)\n";
      return 2;
    }
  }
  absl::StatusOr<dynsolid::server::ReplayReport> r = dynsolid::server::ReplayAnimation(session, o);
  if (!r.ok()) {
    std::cerr << "dynsolid-replay: " << r.status().message() << "\n";
    return r.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }
  std::vector<std::string> files;
  for (const std::string& f : r->files) files.push_back(absl::StrCat("\"", f, "\""));
  std::cout << "{\"frames\": " << r->frames << ", \"steps\": [" << absl::StrJoin(r->frame_steps, ", ")
            << "], \"times\": [" << absl::StrJoin(r->frame_times, ", ", [](std::string* out, double t) { absl::StrAppend(out, absl::StrFormat("%.17g", t)); }) << "], \"journal_records\": "
            << r->journal_records << ", \"end_step\": " << r->end_step
            << ", \"milliseconds\": " << r->milliseconds << ", \"files\": ["
            << absl::StrJoin(files, ", ") << "]}" << std::endl;
  return 0;
}
