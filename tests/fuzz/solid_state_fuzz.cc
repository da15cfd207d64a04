// Fuzzes restoring a solid's saved state (solid::Solid::RestoreState, the
// bytes of a snapshot and of every undo entry) and a whole session snapshot
// (SimCore::RestoreFrom on a persist::Snapshot, what recovery reads from
// snapshot.binpb). One small solid (block3 at level 0, with gravity, a
// point force, a drag and a fixed region, stepped a little) is built once.
//
// Input: the first byte is a mode, the rest the bytes.
//   0: RestoreState(the bytes as they are);
//   1: the same after fixing the header's fingerprint and payload size and
//      the checksum for the version the bytes name (3, 4, or 5 and later),
//      so mutations get past the checksum into the parser;
//   2: parse the bytes as a persist::Snapshot (solid_state fixed as in 1)
//      and RestoreFrom it. Snapshots naming an edited scene are skipped:
//      building a solid from a fuzzed scene is the scene target's concern.
//
// Invariants: no crash or sanitizer report; a refused state leaves the
// solid bit-identical (SaveState before == after; for a snapshot, the
// core's SaveTo as well). An accepted one is undone by restoring the
// original, which must succeed.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>

#include <google/protobuf/text_format.h>

#include "dynsolid/journal.pb.h"
#include "solver/solid/state_codec.h"
#include "tests/fuzz/fuzz_core.h"
#include "tests/fuzz/fuzz_proto.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace fz = dynsolid::fuzz;

// Version 3's byte checksum (solver/solid/state_codec.cc keeps its own to
// itself); versions 4 and later are summed with the library's
// WordChecksum and CombinedChecksum (solver/solid/state_codec.h).
uint64_t ByteSum(std::string_view b) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : b) h = (h ^ c) * 1099511628211ull;
  return h;
}

constexpr size_t kHeader = 8 + 4 + 16 + 8;  // magic, version, fingerprint, payload size

struct Fixture {
  std::unique_ptr<dynsolid::server::SimCore> core;
  std::string state;     // SaveState of the solid
  std::string snapshot;  // SaveTo, serialized
};

// `bytes` with the fingerprint of `state` (the solid's), a payload size
// that matches and a correct checksum; unchanged when too short to have a
// header.
std::string Fix(std::string bytes, const std::string& state) {
  if (bytes.size() < kHeader + 8) return bytes;
  std::memcpy(bytes.data() + 12, state.data() + 12, 16);
  const uint64_t payload = bytes.size() - kHeader - 8;
  std::memcpy(bytes.data() + 28, &payload, 8);
  uint32_t version;
  std::memcpy(&version, bytes.data() + 8, 4);
  const std::string_view body(bytes.data(), bytes.size() - 8);
  uint64_t sum;
  if (version == 3) {
    sum = ByteSum(body);
  } else if (version == 4) {
    sum = dynsolid::solid::WordChecksum(body);
  } else {
    uint64_t n = 0;
    if (payload >= 8) std::memcpy(&n, bytes.data() + bytes.size() - 16, 8);
    if (payload < 8 || n > payload - 8) return bytes;
    const size_t at = bytes.size() - 16 - n;
    sum = dynsolid::solid::CombinedChecksum(
        dynsolid::solid::WordChecksum(body.substr(0, at)),
        dynsolid::solid::WordChecksum(std::string_view(bytes).substr(at, n)), n);
  }
  std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
  return bytes;
}

std::string SnapshotBytes(const dynsolid::server::SimCore& core) {
  dynsolid::persist::Snapshot s;
  core.SaveTo(&s);
  std::string out;
  s.SerializeToString(&out);  // deterministic enough within one process
  return out;
}

Fixture& F() {
  static Fixture* f = [] {
    auto* f = new Fixture;
    fz::FuzzCore maker;
    f->core = maker.Make();
    const char* commands[] = {
        "set_gravity { z: -9.81 }",
        "add_point_force { position { x: 1.5 y: 1.5 z: 3 } force { x: 0.5 z: -2 } }",
        ("drag { material_point { x: 0.5 y: 0.5 z: 3 } target { x: 0.7 y: 0.5 z: 3.2 } "
         "stiffness: 2e4 }"),
        "fix_region { box { min { x: -1 y: -1 z: -1 } max { x: 4 y: 4 z: 0.1 } } }",
    };
    uint64_t seq = 0;
    for (const char* text : commands) {
      dynsolid::CommandRequest r;
      r.set_client_id("seed");
      r.set_seq(++seq);
      if (!google::protobuf::TextFormat::ParseFromString(text, r.mutable_command())) std::abort();
      dynsolid::CommandReply reply;
      f->core->Process(r, &reply);
      if (reply.code() != 0) {
        std::fprintf(stderr, "seed command %s: %s\n", text, reply.message().c_str());
        std::abort();
      }
    }
    for (int i = 0; i < 5; ++i) {
      if (!f->core->StepOnce().ok()) std::abort();
    }
    f->state = f->core->solid().SaveState();
    f->snapshot = SnapshotBytes(*f->core);
    if (Fix(f->state, f->state) != f->state) {
      std::fprintf(stderr, "solid_state_fuzz: the checksums here no longer match "
                           "solver/solid/solid_state.cc; update Fix()\n");
      std::abort();
    }
    return f;
  }();
  return *f;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  dynsolid::fuzz::QuietProtobuf();
  Fixture& f = F();
  const std::string dir = fz::SeedDir();
  if (!dir.empty()) {
    fz::WriteFile(dir + "/state_raw", std::string(1, '\0') + f.state);
    fz::WriteFile(dir + "/state_fixed", std::string(1, '\1') + f.state);
    fz::WriteFile(dir + "/snapshot", std::string(1, '\2') + f.snapshot);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  Fixture& f = F();
  const uint8_t mode = data[0];
  std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  dynsolid::solid::Solid& solid = f.core->solid();

  if (mode == 0 || mode == 1) {
    if (mode == 1) bytes = Fix(std::move(bytes), f.state);
    const absl::Status s = solid.RestoreState(bytes);
    const std::string after = solid.SaveState();
    if (!s.ok()) {
      FUZZ_CHECK(after == f.state, "a refused state changed the solid (%s)",
                 std::string(s.message()).c_str());
      return 0;
    }
    FUZZ_CHECK(solid.RestoreState(f.state).ok(), "cannot restore the original state");
    FUZZ_CHECK(solid.SaveState() == f.state, "the original state does not come back");
    return 0;
  }
  if (mode == 2) {
    dynsolid::persist::Snapshot snapshot;
    if (!snapshot.ParseFromString(bytes)) return 0;
    if (snapshot.scene() != -1) return 0;
    snapshot.set_solid_state(Fix(snapshot.solid_state(), f.state));
    const absl::Status s = f.core->RestoreFrom(snapshot);
    if (!s.ok()) {
      FUZZ_CHECK(f.core->solid().SaveState() == f.state, "a refused snapshot changed the solid (%s)",
                 std::string(s.message()).c_str());
      FUZZ_CHECK(SnapshotBytes(*f.core) == f.snapshot, "a refused snapshot changed the core (%s)",
                 std::string(s.message()).c_str());
      return 0;
    }
    dynsolid::persist::Snapshot original;
    FUZZ_CHECK(original.ParseFromString(f.snapshot), "the original snapshot does not parse");
    const absl::Status back = f.core->RestoreFrom(original);
    FUZZ_CHECK(back.ok(), "cannot restore the original snapshot: %s",
               std::string(back.message()).c_str());
    FUZZ_CHECK(f.core->solid().SaveState() == f.state, "the original state does not come back");
  }
  return 0;
}
