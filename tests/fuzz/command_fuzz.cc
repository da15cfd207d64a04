// Fuzzes command handling the way a Commands stream drives it, without a
// network: the bytes are parsed as a dynsolid.CommandRequest (what a client
// sends), checked as server/streams.cc does (scene::ValidateValues over the request,
// CheckCommandEnvelope), then, as server/session_loop.cc does, stamped if
// it needs a build and processed by a session's core (SimCore::Process:
// every command's validation and application: loads, drags, curves, fixes,
// paints, topology edits, undo and redo, step and pause). An applied
// command is followed by two steps.
//
// The core: block3 at level 0 with gravity, a point force (load 1), a
// drag, a curve, a fixed region and their undo history, built once; after
// each input it is put back with SimCore::RestoreFrom(its snapshot).
//
// Invariants: no crash or sanitizer report; a refused command leaves the
// solid bit-identical (SaveState before == after), as the service
// promises; the core comes back to its snapshot after every input.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <google/protobuf/text_format.h>

#include "dynsolid/journal.pb.h"
#include "solver/scene/scene_loader.h"
#include "tests/fuzz/fuzz_core.h"
#include "tests/fuzz/fuzz_proto.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace fz = dynsolid::fuzz;
using dynsolid::CommandReply;
using dynsolid::CommandRequest;
using dynsolid::server::SimCore;

// Commands the base core starts from, and seeds.
const char* const kSetup[] = {
    "set_gravity { z: -9.81 }",
    "add_point_force { position { x: 1.5 y: 1.5 z: 3 } force { x: 0.5 z: -2 } }",
    ("drag { material_point { x: 0.5 y: 0.5 z: 3 } target { x: 0.7 y: 0.5 z: 3.2 } "
     "stiffness: 2e4 }"),
    ("curve { material_points { x: 0.5 y: 2.5 z: 3 } material_points { x: 2.5 y: 2.5 z: 3 } "
     "targets { x: 0.5 y: 2.5 z: 3.2 } targets { x: 2.5 y: 2.5 z: 3.2 } stiffness: 1e3 "
     "samples: 5 }"),
    "fix_region { box { min { x: -1 y: -1 z: -1 } max { x: 4 y: 4 z: 0.1 } } }",
};

const char* const kSeeds[] = {
    "add_point_force { position { x: 2 y: 1 z: 3 } force { y: 1 } }",
    ("add_pressure { region { box { min { x: -1 y: -1 z: 2.9 } max { x: 4 y: 4 z: 3.1 } } } "
     "pascals: 100 }"),
    "set_gravity { x: 1 z: -9.81 }",
    "remove_load { load_id: 2 }",
    "fix_region { sphere { center { x: 3 y: 3 z: 3 } radius: 0.5 } }",
    "unfix { constraint_id: 6 }",
    ("paint_material { region { sphere { center { x: 1.5 y: 1.5 z: 3 } radius: 1 } } "
     "material { young_modulus: 5e5 density: 3000 damping: 100 } strength: 1 }"),
    "pause {}",
    "resume {}",
    "step { count: 3 }",
    "save {}",
    "edit { extrude_faces { near { x: 0.5 y: 1.5 z: 3 } distance: 0.4 } }",
    "edit { delete_cells { near { x: 0.5 y: 0.5 z: 2.5 } } }",
    "edit { subdivide_cells { cells: 13 } }",
    "edit { merge_faces { near { x: 1 y: 1.5 z: 3.75 } near { x: 2 y: 1.5 z: 3.75 } } }",
    "edit { bake {} }",
    ("drag { material_point { x: 1.5 y: 1.5 z: 3 } target { x: 2.0 y: 1.5 z: 3.3 } "
     "stiffness: 2e4 }"),
    "move_drag { load_id: 3 target { x: 0.9 y: 0.5 z: 3.3 } }",
    "move_drag { load_id: 4 targets { x: 0.5 y: 2.4 z: 3.3 } targets { x: 2.5 y: 2.6 z: 3.5 } }",
    "undo {}",
    "redo {}",
};

CommandRequest Request(const std::string& client, uint64_t seq, const char* text) {
  CommandRequest r;
  r.set_client_id(client);
  r.set_seq(seq);
  if (!google::protobuf::TextFormat::ParseFromString(text, r.mutable_command())) {
    std::fprintf(stderr, "command_fuzz: bad command text %s\n", text);
    std::abort();
  }
  return r;
}

struct Fixture {
  std::unique_ptr<SimCore> core;
  dynsolid::persist::Snapshot base;
  std::string base_bytes;
};

std::string SnapshotBytes(const SimCore& core) {
  // As the session loop writes one: SaveTo's loop state and answer caches,
  // the solid's own state beside them.
  dynsolid::persist::Snapshot s;
  core.SaveTo(&s);
  s.set_solid_state(core.solid().SaveState());
  return s.SerializeAsString();
}

Fixture& F() {
  static Fixture* f = [] {
    auto* f = new Fixture;
    fz::FuzzCore maker;
    f->core = maker.Make();
    uint64_t seq = 0;
    for (const char* text : kSetup) {
      CommandReply reply;
      f->core->Process(Request("setup", ++seq, text), &reply);
      if (reply.code() != 0) {
        std::fprintf(stderr, "command_fuzz: setup %s: %s\n", text, reply.message().c_str());
        std::abort();
      }
    }
    for (int i = 0; i < 3; ++i) {
      if (!f->core->StepOnce().ok()) std::abort();
    }
    f->base_bytes = SnapshotBytes(*f->core);
    if (!f->base.ParseFromString(f->base_bytes)) std::abort();
    return f;
  }();
  return *f;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  dynsolid::fuzz::QuietProtobuf();
  const std::string dir = fz::SeedDir();
  if (!dir.empty()) {
    int k = 0;
    for (const char* text : kSeeds) {
      fz::WriteFile(dir + "/command_" + std::to_string(k++),
                    Request("fuzz", 1, text).SerializeAsString());
    }
    std::exit(0);
  }
  (void)F();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  CommandRequest request;
  if (!request.ParseFromArray(data, static_cast<int>(size))) return 0;
  (void)dynsolid::scene::ValidateValues(request, "");
  if (!dynsolid::server::CheckCommandEnvelope(request).ok()) return 0;

  Fixture& f = F();
  SimCore& core = *f.core;
  if (core.NeedsBuild(request)) core.Stamp(request);
  const std::string before = core.solid().SaveState();
  CommandReply reply;
  const SimCore::Outcome outcome = core.Process(request, &reply);
  if (outcome == SimCore::Outcome::kRejected) {
    FUZZ_CHECK(reply.code() != 0 && !reply.message().empty(),
               "a refused command without a code or a message");
    FUZZ_CHECK(core.solid().SaveState() == before, "a refused command changed the solid: %s",
               reply.message().c_str());
  } else if (outcome == SimCore::Outcome::kApplied) {
    FUZZ_CHECK(reply.code() == 0, "an applied command with code %d", reply.code());
    for (int i = 0; i < 2; ++i) (void)core.StepOnce();
  }
  const absl::Status back = core.RestoreFrom(f.base);
  FUZZ_CHECK(back.ok(), "cannot restore the base snapshot: %s",
             std::string(back.message()).c_str());
  FUZZ_CHECK(SnapshotBytes(core) == f.base_bytes, "the core does not come back to its snapshot");
  return 0;
}
