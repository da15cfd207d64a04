// Exact state (Solid::SaveState / RestoreState): a restored solid goes on
// bit for bit, for any model, integrator and thread count, and corrupt,
// foreign or old-format states are handled as documented.
#include <cstdint>
#include <cstring>
#include <string>
#include <tuple>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/solid/solid.h"
#include "solver/solid/state_codec.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::solid {
namespace {

using ::dynsolid::testing::Parse;
using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

std::unique_ptr<Solid> Make(const std::string& text) { return testing::MakeSolid(text); }

// Runs a script of edits on a solid up to step `until` (edits happen
// before the step of their number).
void RunScript(Solid& s, int from, int until) {
  for (int k = from; k < until; ++k) {
    switch (k) {
      case 3:
        ASSERT_OK(s.SetGravity(Parse<Vec3>("z: -9.81")));
        break;
      case 5:
        ASSERT_OK(s.AddPointForce(Parse<PointForce>("position { x: 1.9 y: 0.5 z: 0.5 } force { z: -40 y: 10 }")));
        break;
      case 8:
        ASSERT_OK(s.FixRegion(Parse<Region>("box { min { x: 1.9 y: -1 z: -1 } max { x: 2.1 y: 2 z: 0.1 } }")));
        break;
      case 10:
        ASSERT_OK(s.PaintMaterial(Parse<MaterialPaint>(
            "region { sphere { center { x: 1 y: 0.5 z: 0.5 } radius: 0.6 } } "
            "material { young_modulus: 4e5 density: 1500 damping: 100 } strength: 0.7")));
        break;
      case 12:
        ASSERT_OK(s.AddPressure(Parse<Pressure>(
            "region { box { min { x: -1 y: -1 z: 0.9 } max { x: 3 y: 2 z: 2 } } } pascals: -500")));
        break;
      case 18:
        ASSERT_OK(s.Unfix(s.constraint_ids().back()));
        break;
      default:
        break;
    }
    ASSERT_OK(s.Step());
  }
}

std::string EditScene(const std::string& model, const std::string& integrator) {
  return absl::StrCat(R"pb(
    mesh { block { nx: 2 ny: 1 nz: 1 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 2e5 density: 1000 } }
    constraints { fixed { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } } } }
    solver { model: )pb", model, " integrator: ", integrator, " time_step: 2e-3 }");
}

class SaveRestoreTest : public ::testing::TestWithParam<std::tuple<const char*, const char*>> {};

TEST_P(SaveRestoreTest, RestoredSolidContinuesBitIdentically) {
  const std::string text = EditScene(std::get<0>(GetParam()), std::get<1>(GetParam()));
  auto a = Make(text);
  ASSERT_NE(a, nullptr);
  // Uninterrupted: 30 steps with every kind of edit; saved at 15 and 25.
  RunScript(*a, 0, 15);
  const std::string at15 = a->SaveState();
  RunScript(*a, 15, 25);
  const std::string at25 = a->SaveState();
  RunScript(*a, 25, 40);
  EXPECT_EQ(a->rollbacks(), 0);
  for (const auto& [from, saved] : {std::pair{15, at15}, std::pair{25, at25}}) {
    auto b = Make(text);
    ASSERT_NE(b, nullptr);
    ASSERT_OK(b->RestoreState(saved));
    EXPECT_EQ(b->SaveState(), saved) << "restore then save gives the same bytes";
    EXPECT_EQ(b->steps(), from);
    RunScript(*b, from, 40);
    EXPECT_EQ(b->control_positions(), a->control_positions()) << "restored at step " << from;
    EXPECT_EQ(b->time(), a->time());
    EXPECT_EQ(b->SaveState(), a->SaveState()) << "restored at step " << from;
  }
}

INSTANTIATE_TEST_SUITE_P(
    ModelsAndIntegrators, SaveRestoreTest,
    ::testing::Values(std::tuple{"LOCAL_FRAME", "CENTRAL_DIFFERENCE"},
                      std::tuple{"COROTATIONAL", "CENTRAL_DIFFERENCE"},
                      std::tuple{"COROTATIONAL", "BACKWARD_EULER"}),
    [](const auto& info) {
      return absl::StrCat(std::get<0>(info.param), "_", std::get<1>(info.param));
    });

TEST(SolidRuntimeTest, EditsGiveTheSameBitsForAnyThreadCount) {
  const std::string text = EditScene("LOCAL_FRAME", "CENTRAL_DIFFERENCE");
  std::vector<std::string> states;
  for (const char* threads : {"1", "2", "3"}) {
    auto s = testing::WithThreadsEnv(threads, [&] { return Make(text); });
    ASSERT_NE(s, nullptr);
    RunScript(*s, 0, 25);
    states.push_back(s->SaveState());
  }
  EXPECT_EQ(states[0], states[1]) << "1 and 2 threads";
  EXPECT_EQ(states[0], states[2]) << "1 and 3 threads";
}

// The state of a solid of `text` after the script's first 12 steps.
std::string StateAfterScript(const std::string& text) {
  auto a = Make(text);
  if (a == nullptr) return "";
  RunScript(*a, 0, 12);
  return a->SaveState();
}

TEST(SolidRuntimeTest, CorruptOrForeignStatesAreRejectedAndChangeNothing) {
  const std::string text = EditScene("LOCAL_FRAME", "CENTRAL_DIFFERENCE");
  const std::string saved = StateAfterScript(text);
  ASSERT_FALSE(saved.empty());
  auto b = Make(text);
  ASSERT_NE(b, nullptr);
  const std::string fresh = b->SaveState();
  // Every single flipped byte (a sample of them) is caught.
  for (size_t i = 8 + 4; i < saved.size(); i += saved.size() / 97 + 1) {
    std::string bad = saved;
    bad[i] ^= 0x20;
    EXPECT_THAT(b->RestoreState(bad), StatusIs(absl::StatusCode::kDataLoss, HasSubstr("checksum")))
        << "byte " << i;
  }
  EXPECT_THAT(b->RestoreState(saved.substr(0, saved.size() - 100)),
              StatusIs(absl::StatusCode::kDataLoss, HasSubstr("corrupt or truncated")));
  std::string version = saved;
  version[8] = 7;
  EXPECT_THAT(b->RestoreState(version),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("format version 7")));
  EXPECT_THAT(b->RestoreState(""),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("not a dynsolid solid state")));
  // Another scene (another material), same mesh.
  std::string other_text = text;
  other_text.replace(other_text.find("2e5"), 3, "3e5");
  auto other = Make(other_text);
  ASSERT_NE(other, nullptr);
  EXPECT_THAT(other->RestoreState(saved),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("fingerprint mismatch")));
  EXPECT_EQ(b->SaveState(), fresh) << "failed restores change nothing";
  ASSERT_OK(b->RestoreState(saved));
  EXPECT_EQ(b->SaveState(), saved);
  // A version 3 state (versions 3 and 4 put the material samples before
  // the frames, with no section length; version 3 sums bytes with FNV-1a)
  // is still read, and saved again as the current version. Made here from
  // the version 6 bytes: header, loads and the rest, frames (per kind a
  // count and 4 doubles per element), the material section (arrays, then
  // per kind a count and an int32 per element), its length, the checksum.
  ASSERT_EQ(saved[8], static_cast<char>(Solid::kStateFormatVersion));
  auto u64 = [&](size_t at) {
    uint64_t v;
    std::memcpy(&v, saved.data() + at, 8);
    return v;
  };
  const size_t section_bytes = u64(saved.size() - 16);
  const size_t section_at = saved.size() - 16 - section_bytes;
  size_t at = section_at;
  const uint64_t arrays = u64(at);
  at += 8;
  for (uint64_t k = 0; k < arrays; ++k) at += 8 + 8 * u64(at);
  size_t frames_bytes = 0;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const uint64_t count = u64(at);
    at += 8 + 4 * count;
    frames_bytes += 8 + 32 * count;
  }
  ASSERT_EQ(at, section_at + section_bytes);
  const size_t frames_at = section_at - frames_bytes;
  // Version 6 put two byte strings before the frames (the environment's
  // contacts and clay's state: empty here, 8 bytes of length each).
  ASSERT_EQ(u64(frames_at - 16), 0u);
  ASSERT_EQ(u64(frames_at - 8), 0u);
  std::string v3 = saved.substr(0, frames_at - 16) + saved.substr(section_at, section_bytes) +
                   saved.substr(frames_at, frames_bytes) + std::string(8, '\0');
  v3[8] = 3;
  const uint64_t payload = v3.size() - 36 - 8;
  std::memcpy(v3.data() + 28, &payload, 8);
  uint64_t h = 1469598103934665603ull;
  for (size_t i = 0; i + 8 < v3.size(); ++i) h = (h ^ static_cast<unsigned char>(v3[i])) * 1099511628211ull;
  std::memcpy(v3.data() + v3.size() - 8, &h, 8);
  auto c = Make(text);
  ASSERT_NE(c, nullptr);
  ASSERT_OK(c->RestoreState(v3));
  EXPECT_EQ(c->SaveState(), saved);
  v3[100] ^= 0x20;
  EXPECT_THAT(c->RestoreState(v3), StatusIs(absl::StatusCode::kDataLoss, HasSubstr("checksum")));
}

// ResealState (what fuzzers use to reach past the header) reproduces a
// saved state's own size and checksum, and makes an edited state's
// checksum right again, so that what is wrong with it is found further in.
TEST(SolidRuntimeTest, ResealStateRecomputesTheChecksumOfEditedBytes) {
  const std::string saved = StateAfterScript(EditScene("LOCAL_FRAME", "CENTRAL_DIFFERENCE"));
  ASSERT_FALSE(saved.empty());
  std::string same = saved;
  ASSERT_TRUE(ResealState(same));
  EXPECT_EQ(same, saved);
  // A flipped byte in the material section's samples: the checksum
  // catches it; resealed, the header passes and the state reads.
  std::string bad = saved;
  bad[saved.size() - 40] ^= 0x01;
  ASSERT_NE(bad, saved);
  EXPECT_THAT(ReadStateHeader(bad, Solid::kStateFormatVersion), StatusIs(absl::StatusCode::kDataLoss, HasSubstr("checksum")));
  ASSERT_TRUE(ResealState(bad));
  EXPECT_OK(ReadStateHeader(bad, Solid::kStateFormatVersion));
  // A truncated state gets the payload size that matches, but no checksum
  // where its section length no longer fits.
  std::string cut = saved.substr(0, 60);
  EXPECT_FALSE(ResealState(cut));
  std::string tiny = "DSOLIDST";
  EXPECT_FALSE(ResealState(tiny));
  EXPECT_EQ(tiny, "DSOLIDST");
}

}  // namespace
}  // namespace dynsolid::solid
