// Units below the service: the surface codec (keyframes and quantized
// deltas), the journal framing with torn tails, atomic files, and the
// non-finite scan of requests.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "server/journal.h"
#include "clients/lib/surface.h"
#include "server/surface_codec.h"
#include "temp_dir.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::server {
namespace {

using ::dynsolid::testing::TempDir;
using ::testing::HasSubstr;

// A 20 x 20 grid of vertices on a 2 m square at z = 0, quads between.
std::shared_ptr<SurfaceTopology> GridTopology(int n = 20) {
  auto t = std::make_shared<SurfaceTopology>();
  t->vertex_count = n * n;
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const int v = i + n * j;
      t->quads.insert(t->quads.end(), {v, v + 1, v + 1 + n, v + n});
    }
  }
  for (int v = 0; v < n * n; ++v) t->nodes.push_back(v);
  return t;
}

std::shared_ptr<SurfaceSnapshot> Wave(std::shared_ptr<const SurfaceTopology> topo, int64_t step,
                                      double amplitude, double phase) {
  auto s = std::make_shared<SurfaceSnapshot>();
  s->step = step;
  s->time = step * 1e-3;
  s->topology = topo;
  const int n = static_cast<int>(std::lround(std::sqrt(topo->vertex_count)));
  for (int v = 0; v < topo->vertex_count; ++v) {
    const double x = 2.0 * (v % n) / (n - 1), y = 2.0 * (v / n) / (n - 1);
    s->positions.insert(s->positions.end(),
                        {x, y, 0.5 + amplitude * std::sin(3 * x + phase) * std::cos(2 * y)});
  }
  return s;
}

// Largest |decoded - server| per axis, divided by the stated bound.
double WorstRatio(const client::SurfaceDecoder& d, const SurfaceSnapshot& s) {
  const std::vector<double> p = d.surface().positions;
  EXPECT_EQ(p.size(), s.positions.size());
  const double bound[3] = {d.surface().error_bound[0], d.surface().error_bound[1], d.surface().error_bound[2]};
  double worst = 0;
  for (size_t i = 0; i < p.size() && i < s.positions.size(); ++i) {
    worst = std::max(worst, std::abs(p[i] - s.positions[i]) / bound[i % 3]);
  }
  return worst;
}

// The default grid through an encoder and the decoder of its frames.
struct GridCodec {
  std::shared_ptr<SurfaceTopology> topo = GridTopology();
  SurfaceEncoder enc{FieldChoice{}};
  client::SurfaceDecoder dec;
  Frame frame;

  // Encodes the grid at rest at step 0 into `frame` (a keyframe) and
  // applies it; the decoder's status.
  absl::Status EncodeRestAndApply() {
    enc.Encode(Wave(topo, 0, 0.2, 0), &frame);
    return dec.Apply(frame);
  }
};

TEST(SurfaceCodecTest, KeyframeThenDeltasReconstructWithinTheStatedBound) {
  auto topo = GridTopology();
  SurfaceEncoder enc(FieldChoice{});
  client::SurfaceDecoder dec;
  Frame frame;
  int keyframes = 0;
  for (int k = 0; k < 60; ++k) {
    auto snap = Wave(topo, 10 * k, 0.2, 0.05 * k);
    keyframes += enc.Encode(snap, &frame);
    ASSERT_TRUE(dec.Apply(frame).ok()) << "frame " << k;
    EXPECT_EQ(dec.step(), 10 * k);
    // Half a step of 65535 across the grid, plus rounding of the decode.
    EXPECT_LE(WorstRatio(dec, *snap), 1.0 + 1e-9) << "frame " << k;
  }
  EXPECT_EQ(keyframes, 1);
  EXPECT_TRUE(frame.has_delta());
  EXPECT_EQ(dec.surface().quads.size(), topo->quads.size());
}

TEST(SurfaceCodecTest, TheBoundIsHalfAGridStepOfTheWidenedBox) {
  auto topo = GridTopology();
  SurfaceEncoder enc(FieldChoice{});
  Frame frame;
  enc.Encode(Wave(topo, 0, 0.2, 0), &frame);
  ASSERT_TRUE(frame.has_keyframe());
  const Keyframe& k = frame.keyframe();
  // x spans [0, 2]: widened by 25 % each side -> 3 m over 65535 steps.
  EXPECT_DOUBLE_EQ(k.grid().step().x(), 3.0 / 65535);
  EXPECT_DOUBLE_EQ(k.error_bound().x(), 1.5 / 65535);
  EXPECT_DOUBLE_EQ(k.grid().origin().x(), -0.5);
  EXPECT_EQ(k.codes().size(), 6u * 400);
}

TEST(SurfaceCodecTest, UnmovedSurfaceSendsAnEmptyDelta) {
  GridCodec c;
  ASSERT_TRUE(c.EncodeRestAndApply().ok());
  c.enc.Encode(Wave(c.topo, 5, 0.2, 0), &c.frame);
  ASSERT_TRUE(c.frame.has_delta());
  EXPECT_EQ(c.frame.delta().moved(), 0);
  EXPECT_EQ(c.frame.delta().runs_size(), 0);
  EXPECT_EQ(c.frame.delta().base_step(), 0);
  ASSERT_TRUE(c.dec.Apply(c.frame).ok());
  EXPECT_EQ(c.dec.step(), 5);
}

TEST(SurfaceCodecTest, SmallMotionDeltasAreUnderAQuarterOfRawFloat32Frames) {
  auto topo = GridTopology(40);
  SurfaceEncoder enc(FieldChoice{});
  Frame frame;
  enc.Encode(Wave(topo, 0, 0.2, 0), &frame);
  // Every vertex moves a little each frame (a wobbling surface).
  size_t worst = 0;
  for (int k = 1; k < 20; ++k) {
    enc.Encode(Wave(topo, k, 0.2, 0.002 * k), &frame);
    ASSERT_TRUE(frame.has_delta());
    worst = std::max(worst, frame.ByteSizeLong());
  }
  const size_t raw = 12u * topo->vertex_count;
  EXPECT_LE(worst * 4, raw) << "delta " << worst << " bytes, raw float32 " << raw;
}

// Encodes `snap` into `frame`: a delta with `rice_k_size` Rice parameters
// and `bits` fixed-width bits, which `dec` applies within the bound.
void ExpectDelta(SurfaceEncoder& enc, client::SurfaceDecoder& dec, Frame& frame,
                 const std::shared_ptr<SurfaceSnapshot>& snap, int rice_k_size, uint32_t bits) {
  enc.Encode(snap, &frame);
  ASSERT_TRUE(frame.has_delta());
  EXPECT_EQ(frame.delta().rice_k_size(), rice_k_size);
  EXPECT_EQ(frame.delta().bits(), bits);
  ASSERT_TRUE(dec.Apply(frame).ok());
  EXPECT_LE(WorstRatio(dec, *snap), 1.0 + 1e-9);
}

TEST(SurfaceCodecTest, DeltasUseRiceCodesOrFixedWidthWhicheverIsShorter) {
  auto topo = GridTopology();
  SurfaceEncoder enc(FieldChoice{});
  client::SurfaceDecoder dec;
  Frame frame;
  auto base = Wave(topo, 0, 0.2, 0);
  enc.Encode(base, &frame);
  ASSERT_TRUE(dec.Apply(frame).ok());
  // Small moves everywhere and one large outlier: Rice is shorter.
  auto mixed = std::make_shared<SurfaceSnapshot>(*base);
  mixed->step = 1;
  for (size_t i = 0; i < mixed->positions.size(); ++i) mixed->positions[i] += 1e-4 * (i % 7);
  mixed->positions[0] += 0.3;
  ASSERT_NO_FATAL_FAILURE(ExpectDelta(enc, dec, frame, mixed, /*rice_k_size=*/3, /*bits=*/0u));
  // Every vertex moved by the same 5 codes on every axis: fixed width
  // (4 bits each) is shorter than any Rice code.
  Frame key;
  SurfaceEncoder enc2(FieldChoice{});
  client::SurfaceDecoder dec2;
  enc2.Encode(base, &key);
  ASSERT_TRUE(dec2.Apply(key).ok());
  const Keyframe& k = key.keyframe();
  const double sx = k.grid().step().x(), sy = k.grid().step().y(), sz = k.grid().step().z();
  auto shifted = std::make_shared<SurfaceSnapshot>(*base);
  shifted->step = 1;
  const std::vector<double> start = dec2.surface().positions;
  for (size_t i = 0; i < start.size(); i += 3) {
    shifted->positions[i] = start[i] + 5 * sx;
    shifted->positions[i + 1] = start[i + 1] + 5 * sy;
    shifted->positions[i + 2] = start[i + 2] + 5 * sz;
  }
  ASSERT_NO_FATAL_FAILURE(ExpectDelta(enc2, dec2, key, shifted, /*rice_k_size=*/0, /*bits=*/4u));
}

TEST(SurfaceCodecTest, LeavingTheGridOrChangingTopologyGivesAKeyframe) {
  auto topo = GridTopology();
  SurfaceEncoder enc(FieldChoice{});
  client::SurfaceDecoder dec;
  Frame frame;
  EXPECT_TRUE(enc.Encode(Wave(topo, 0, 0.2, 0), &frame));
  ASSERT_TRUE(dec.Apply(frame).ok());
  // Translate by a whole box: off the grid.
  auto moved = Wave(topo, 1, 0.2, 0);
  for (size_t i = 0; i < moved->positions.size(); i += 3) moved->positions[i] += 5.0;
  EXPECT_TRUE(enc.Encode(moved, &frame));
  ASSERT_TRUE(dec.Apply(frame).ok());
  EXPECT_LE(WorstRatio(dec, *moved), 1.0 + 1e-9);
  auto retopo = std::make_shared<SurfaceTopology>(*topo);
  retopo->version = 1;
  auto again = Wave(retopo, 2, 0.2, 0);
  for (size_t i = 0; i < again->positions.size(); i += 3) again->positions[i] += 5.0;
  EXPECT_TRUE(enc.Encode(again, &frame));
  EXPECT_EQ(frame.keyframe().topology_version(), 1);
}

TEST(SurfaceCodecTest, AWatcherThatSkippedManyFramesResumesConsistently) {
  // The encoder only ever sees the frames it sent; a big jump in between is
  // either a larger delta or, when that would be bigger, a fresh keyframe.
  GridCodec c;
  ASSERT_TRUE(c.EncodeRestAndApply().ok());
  auto later = Wave(c.topo, 500, 0.2, 2.5);  // everything moved a lot
  c.enc.Encode(later, &c.frame);
  ASSERT_TRUE(c.dec.Apply(c.frame).ok());
  EXPECT_LE(WorstRatio(c.dec, *later), 1.0 + 1e-9);
  EXPECT_EQ(c.dec.step(), 500);
}

TEST(SurfaceCodecTest, FieldsTravelWithKeyframesAndMovedVertices) {
  auto topo = GridTopology(4);
  SurfaceEncoder enc(FieldChoice{true, false, true});
  client::SurfaceDecoder dec;
  Frame frame;
  auto a = Wave(topo, 0, 0.2, 0);
  a->displacement.assign(16, 0.5f);
  a->strain.assign(16, 0.25f);
  a->stiffness.assign(16, 1e5f);
  enc.Encode(a, &frame);
  EXPECT_EQ(frame.keyframe().fields().displacement_size(), 16);
  EXPECT_EQ(frame.keyframe().fields().strain_size(), 0);
  ASSERT_TRUE(dec.Apply(frame).ok());
  auto b = Wave(topo, 1, 0.2, 0.3);
  b->displacement.assign(16, 0.75f);
  b->strain.assign(16, 0.25f);
  b->stiffness.assign(16, 1e5f);
  enc.Encode(b, &frame);
  ASSERT_TRUE(frame.has_delta());
  EXPECT_EQ(frame.delta().fields().displacement_size(), frame.delta().moved());
  ASSERT_TRUE(dec.Apply(frame).ok());
  // A paint changes fields without motion: a keyframe carries them.
  auto c = Wave(topo, 2, 0.2, 0.3);
  c->fields_version = 1;
  c->displacement = b->displacement;
  c->strain = b->strain;
  c->stiffness.assign(16, 2e5f);
  EXPECT_TRUE(enc.Encode(c, &frame));
  ASSERT_TRUE(dec.Apply(frame).ok());
  EXPECT_EQ(dec.surface().stiffness, std::vector<float>(16, 2e5f));
}

TEST(SurfaceCodecTest, MassTravelsBesideTheOtherFieldsAndAMassPaintSendsAKeyframe) {
  auto topo = GridTopology(4);
  SurfaceEncoder enc(FieldChoice{true, true, true, true});
  SurfaceEncoder mass_only(FieldChoice{false, false, false, true});
  client::SurfaceDecoder dec, dec_mass;
  Frame frame;
  auto fill = [](SurfaceSnapshot& s, float density) {
    s.displacement.assign(16, 0.5f);
    s.strain.assign(16, 0.25f);
    s.stiffness.assign(16, 1e5f);
    s.mass.resize(16);
    for (int i = 0; i < 16; ++i) s.mass[i] = density + i;
  };
  auto a = Wave(topo, 0, 0.2, 0);
  fill(*a, 1000);
  EXPECT_TRUE(enc.Encode(a, &frame));
  ASSERT_EQ(frame.keyframe().fields().mass_size(), 16);
  EXPECT_EQ(frame.keyframe().fields().mass(3), 1003.0f);
  const size_t all_four = frame.ByteSizeLong();
  ASSERT_TRUE(dec.Apply(frame).ok());
  EXPECT_EQ(dec.surface().mass, a->mass);
  EXPECT_TRUE(mass_only.Encode(a, &frame));
  EXPECT_EQ(frame.keyframe().fields().mass_size(), 16);
  EXPECT_EQ(frame.keyframe().fields().stiffness_size(), 0);
  EXPECT_LT(frame.ByteSizeLong() + 3 * 16 * 4, all_four + 16) << "one field, not four";
  ASSERT_TRUE(dec_mass.Apply(frame).ok());
  // Motion: the moved vertices carry their mass.
  auto b = Wave(topo, 1, 0.2, 0.3);
  fill(*b, 2000);
  EXPECT_FALSE(enc.Encode(b, &frame));
  ASSERT_TRUE(frame.has_delta());
  EXPECT_GT(frame.delta().moved(), 0);
  EXPECT_EQ(frame.delta().fields().mass_size(), frame.delta().moved());
  ASSERT_TRUE(dec.Apply(frame).ok());
  EXPECT_EQ(dec.surface().mass, b->mass) << "every vertex of the wave moved";
  EXPECT_FALSE(mass_only.Encode(b, &frame));
  EXPECT_EQ(frame.delta().fields().mass_size(), frame.delta().moved());
  EXPECT_EQ(frame.delta().fields().displacement_size(), 0);
  ASSERT_TRUE(dec_mass.Apply(frame).ok());
  EXPECT_EQ(dec_mass.surface().mass, b->mass);
  // A density paint without motion (fields_version moves): a keyframe.
  auto c = Wave(topo, 2, 0.2, 0.3);
  fill(*c, 2000);
  c->fields_version = 1;
  c->mass[5] = 7000;
  EXPECT_TRUE(mass_only.Encode(c, &frame));
  ASSERT_TRUE(dec_mass.Apply(frame).ok());
  EXPECT_EQ(dec_mass.surface().mass, c->mass);
  // Without fields a paint changes nothing on the wire: an empty delta.
  SurfaceEncoder plain(FieldChoice{});
  plain.Encode(b, &frame);
  EXPECT_FALSE(plain.Encode(c, &frame));
  EXPECT_EQ(frame.delta().moved(), 0);
  EXPECT_FALSE(frame.delta().has_fields());
}

TEST(SurfaceCodecTest, WatchersInTheSameStateShareOneEncodingAndConvergeOnOneGrid) {
  auto topo = GridTopology();
  auto cache = std::make_shared<EncodeCache>();
  SurfaceEncoder a(FieldChoice{}, cache), b(FieldChoice{}, cache), alone(FieldChoice{});
  client::SurfaceDecoder da, db, dalone;
  Frame fa, fb, f;
  // a joins at step 0, b at step 1: b keys on a's grid (it still fits).
  auto s0 = Wave(topo, 0, 0.2, 0), s1 = Wave(topo, 1, 0.2, 0.01);
  a.Encode(s0, &fa);
  ASSERT_TRUE(da.Apply(fa).ok());
  alone.Encode(s0, &f);
  ASSERT_TRUE(dalone.Apply(f).ok());
  a.Encode(s1, &fa);
  b.Encode(s1, &fb);
  ASSERT_TRUE(da.Apply(fa).ok());
  ASSERT_TRUE(db.Apply(fb).ok());
  EXPECT_EQ(fb.keyframe().grid().origin().x(), 0 - 0.5);  // s0's grid
  EXPECT_EQ(db.surface().positions, da.surface().positions);
  // From now on both are in the same state: one encoding serves both.
  const int64_t misses = cache->misses();
  for (int k = 2; k < 12; ++k) {
    auto snap = Wave(topo, k, 0.2, 0.01 * k);
    a.Encode(snap, &fa);
    b.Encode(snap, &fb);
    alone.Encode(snap, &f);
    EXPECT_EQ(fa.SerializeAsString(), fb.SerializeAsString()) << k;
    ASSERT_TRUE(da.Apply(fa).ok());
    ASSERT_TRUE(db.Apply(fb).ok());
    ASSERT_TRUE(dalone.Apply(f).ok());
    EXPECT_LE(WorstRatio(db, *snap), 1.0 + 1e-9);
  }
  EXPECT_EQ(cache->misses() - misses, 10);  // one computation per snapshot
  EXPECT_GE(cache->hits(), 10);
  // Sharing changes no bit of what a watcher decodes.
  EXPECT_EQ(da.surface().positions, dalone.surface().positions);
}

TEST(SurfaceCodecTest, SharedBytesWithATrailerAreExactlyEachWatchersFrame) {
  auto topo = GridTopology();
  auto cache = std::make_shared<EncodeCache>();
  SurfaceEncoder a(FieldChoice{true, false, true}, cache), b(FieldChoice{true, false, true}, cache);
  SurfaceEncoder alone(FieldChoice{true, false, true});
  client::SurfaceDecoder da, db, dalone;
  for (int k = 0; k < 8; ++k) {
    auto snap = Wave(topo, k, 0.2, 0.01 * k);
    snap->displacement.assign(topo->vertex_count, 0.5f * k);
    snap->stiffness.assign(topo->vertex_count, 1e5f);
    std::shared_ptr<const EncodeCache::Result> ra = a.EncodeShared(snap);
    std::shared_ptr<const EncodeCache::Result> rb = b.EncodeShared(snap);
    Frame f;
    const bool key = alone.Encode(snap, &f);
    ASSERT_NE(ra->bytes, nullptr);
    EXPECT_EQ(ra.get(), rb.get()) << "same state, one shared result, step " << k;
    EXPECT_EQ(ra->keyframe, key) << k;
    EXPECT_EQ(key, k == 0) << k;
    // What two watchers with their own skipped / watcher_id get on the
    // wire, against the frame encoded for one watcher and serialized whole.
    for (const auto& [skipped, id] : {std::pair<int64_t, int64_t>{0, 0}, {k, 7}, {3, 1 << 20}}) {
      const std::string wire = *ra->bytes + FrameTrailer(skipped, id);
      Frame whole = f;
      whole.set_skipped(skipped);
      whole.set_watcher_id(id);
      EXPECT_EQ(wire, whole.SerializeAsString()) << "step " << k << " skipped " << skipped;
    }
    Frame got_a, got_b;
    ASSERT_TRUE(got_a.ParseFromString(*ra->bytes + FrameTrailer(k, 1)));
    ASSERT_TRUE(got_b.ParseFromString(*rb->bytes + FrameTrailer(0, 2)));
    EXPECT_EQ(got_a.skipped(), k);
    EXPECT_EQ(got_a.watcher_id(), 1);
    EXPECT_EQ(got_b.watcher_id(), 2);
    ASSERT_TRUE(da.Apply(got_a).ok()) << k;
    ASSERT_TRUE(db.Apply(got_b).ok()) << k;
    ASSERT_TRUE(dalone.Apply(f).ok()) << k;
    // Bit-identical to the watcher that encoded alone.
    EXPECT_EQ(da.surface().positions, dalone.surface().positions) << k;
    EXPECT_EQ(db.surface().positions, dalone.surface().positions) << k;
    EXPECT_EQ(da.surface().displacement, dalone.surface().displacement) << k;
    EXPECT_EQ(da.surface().stiffness, dalone.surface().stiffness) << k;
    EXPECT_LE(WorstRatio(da, *snap), 1.0 + 1e-9) << k;
  }
  EXPECT_EQ(FrameTrailer(0, 0), "");
}

TEST(SurfaceCodecTest, DecoderRefusesADeltaAgainstAnotherBase) {
  auto topo = GridTopology();
  SurfaceEncoder enc(FieldChoice{});
  client::SurfaceDecoder dec;
  Frame first, second;
  enc.Encode(Wave(topo, 0, 0.2, 0), &first);
  enc.Encode(Wave(topo, 1, 0.2, 0.1), &second);
  EXPECT_EQ(dec.Apply(second).code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(dec.Apply(first).ok());
  Frame bad = second;
  bad.mutable_delta()->set_base_step(7);
  EXPECT_THAT(std::string(dec.Apply(bad).message()), HasSubstr("base_step 7"));
  EXPECT_TRUE(dec.Apply(second).ok());
}

// ---- Journal ----

TEST(JournalTest, Crc32cMatchesTheStandardCheckValue) {
  EXPECT_EQ(Crc32c("123456789"), 0xE3069283u);
  EXPECT_EQ(Crc32c(""), 0u);
}

TEST(JournalTest, RecordsReadBackAndATornTailIsTruncated) {
  TempDir dir("dynsolid_journal");
  const std::string path = dir.path() + "/journal";
  {
    auto w = JournalWriter::Open(path, 0);
    ASSERT_TRUE(w.ok()) << w.status();
    ASSERT_TRUE((*w)->Append(FrameRecord("first")).ok());
    ASSERT_TRUE((*w)->Append(FrameRecord("second record")).ok());
    ASSERT_TRUE((*w)->Sync().ok());
    // A torn third record: the header and half the payload.
    const std::string third = FrameRecord("third, never acknowledged");
    ASSERT_TRUE((*w)->Append(third.substr(0, 8 + 5)).ok());
  }
  auto read = ReadJournal(path, 0);
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->records.size(), 2u);
  EXPECT_EQ(read->records[0], "first");
  EXPECT_EQ(read->records[1], "second record");
  EXPECT_EQ(read->valid_end, 8u + 5 + 8 + 13);
  EXPECT_EQ(read->file_bytes, read->valid_end + 13);
  EXPECT_THAT(read->tail_problem, HasSubstr("torn record"));
  // Reopening at valid_end drops the tail; appending continues cleanly.
  {
    auto w = JournalWriter::Open(path, read->valid_end);
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE((*w)->Append(FrameRecord("third")).ok());
  }
  read = ReadJournal(path, 0);
  ASSERT_TRUE(read.ok());
  ASSERT_EQ(read->records.size(), 3u);
  EXPECT_EQ(read->records[2], "third");
  EXPECT_TRUE(read->tail_problem.empty());
  // From an offset (a snapshot's): the records after it.
  read = ReadJournal(path, 8 + 5);
  ASSERT_TRUE(read.ok());
  ASSERT_EQ(read->records.size(), 2u);
  EXPECT_EQ(read->records[0], "second record");
}

TEST(JournalTest, ACorruptedRecordEndsTheValidPrefix) {
  TempDir dir("dynsolid_journal");
  const std::string path = dir.path() + "/journal";
  std::string bytes = FrameRecord("alpha") + FrameRecord("beta");
  bytes[8 + 5 + 8 + 1] ^= 0x20;  // flip a bit in "beta"
  ASSERT_TRUE(WriteFileAtomically(dir.path(), "journal", bytes).ok());
  auto read = ReadJournal(path, 0);
  ASSERT_TRUE(read.ok());
  ASSERT_EQ(read->records.size(), 1u);
  EXPECT_THAT(read->tail_problem, HasSubstr("bad CRC at byte 13"));
  EXPECT_EQ(ReadJournal(path, 1000).status().code(), absl::StatusCode::kDataLoss);
}

TEST(JournalTest, AtomicFileReplacesContentsAndKeepsItsMode) {
  TempDir dir("dynsolid_journal");
  ASSERT_TRUE(WriteFileAtomically(dir.path(), "f", "one").ok());
  ASSERT_TRUE(WriteFileAtomically(dir.path(), "f", "two, longer").ok());
  auto got = ReadWholeFile(dir.path() + "/f");
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(*got, "two, longer");
  struct stat st;
  ASSERT_EQ(::stat((dir.path() + "/f").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  EXPECT_EQ(::access((dir.path() + "/f.tmp").c_str(), F_OK), -1);
}

// ---- Non-finite scan ----

TEST(FiniteCheckTest, NamesTheFirstNonFiniteFieldByItsPath) {
  Command c;
  c.mutable_add_point_force()->mutable_position()->set_x(1);
  c.mutable_add_point_force()->mutable_force()->set_z(std::numeric_limits<double>::quiet_NaN());
  const absl::Status s = scene::ValidateValues(c, "command");
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "command.add_point_force.force.z must be finite, got nan");

  Scene scene;
  scene.mutable_loads()->add_point_forces();
  scene.mutable_loads()->add_point_forces()->mutable_force()->set_y(
      -std::numeric_limits<double>::infinity());
  EXPECT_EQ(scene::ValidateValues(scene, "scene").message(),
            "scene.loads.point_forces[1].force.y must be finite, got -inf");

  WatchRequest w;
  w.set_rate_hz(std::numeric_limits<double>::infinity());
  EXPECT_EQ(scene::ValidateValues(w, "").message(), "rate_hz must be finite, got inf");
  w.set_rate_hz(30);
  EXPECT_TRUE(scene::ValidateValues(w, "").ok());
}

}  // namespace
}  // namespace dynsolid::server
