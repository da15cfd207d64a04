// Shared test vectors for other decoders of the Watch stream (the browser
// viewer's JavaScript decoder in clients/web): the SERVER's surface encoder
// (server/surface_codec.h, with an EncodeCache and the per-watcher trailer,
// byte for byte what a watcher receives) over a real solid's boundary
// surface (block3 at one level: 218 vertices, 216 quads; painted, dragged,
// stepped, then extruded) with some positions moved by hand to force every
// kind of frame, decoded by the C++ client's SurfaceDecoder (clients/lib).
//
// Written to $DYNSOLID_VECTORS_DIR (created; unset: ./surface_vectors under
// the working directory). CTest runs it as the test `surface_vectors`
// (FIXTURES_SETUP surface_vectors) with the directory
// <build>/test_vectors/surface.
//
//   frames.bin     the frames in order, each as a uint32 little-endian byte
//                  length followed by that many bytes of a serialized
//                  dynsolid.Frame (service.proto).
//   expected.json  a JSON array, one object per frame in the same order:
//     "kind"              what the frame is there for:
//                         "keyframe_first", "delta", "delta_fixed",
//                         "delta_rice_escape", "delta_empty",
//                         "delta_skipped", "keyframe_fields",
//                         "keyframe_rekey", "keyframe_topology"
//     "step", "time"      Frame.step, Frame.time
//     "keyframe"          a Keyframe (else a Delta)
//     "skipped"           Frame.skipped
//     "topology_version"  of the surface the decoder holds after the frame
//     "vertex_count"      its vertices
//     "quads"             its full quad list (4 indices per quad)
//     "positions"         what the client decoder holds after applying the
//                         frame, x y z per vertex (17 significant digits:
//                         the exact doubles)
//     "true_positions"    the exact float64 positions given to the encoder
//     "error_bound"       [x, y, z] half a grid step, metres
//     "fields"            {"displacement", "strain", "stiffness", "mass"}:
//                         the decoder's per-vertex fields after the frame
//                         (float32 values printed as exact doubles; an
//                         array is empty when the stream has no such field)
//     "rice"              a delta in the Rice code (false: fixed width, or
//                         a keyframe)
//     "moved"             Delta.moved (0 for a keyframe)
// Every decoded position is within error_bound of its true position (checked
// here), and the frames include each kind above (checked here too, so the
// vectors cannot silently lose coverage).
#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/lib/surface.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"
#include "server/surface_codec.h"

namespace dynsolid::server {
namespace {

constexpr int64_t kWatcherId = 1;

// Exact text of a double (17 significant digits read back bit for bit).
std::string Num(double v) { return absl::StrFormat("%.17g", v); }

template <typename T>
std::string JsonArray(const std::vector<T>& v) {
  std::string out = "[";
  for (size_t i = 0; i < v.size(); ++i) {
    if (i > 0) out += ",";
    if constexpr (std::is_integral_v<T>) {
      absl::StrAppend(&out, v[i]);
    } else {
      out += Num(static_cast<double>(v[i]));
    }
  }
  return out + "]";
}

// The code of x on one axis of a grid, as the encoder computes it.
int64_t Quantize(double origin, double step, double x) {
  return static_cast<int64_t>(std::nearbyint((x - origin) / step));
}

uint32_t ZigZag(int64_t d) {
  return d >= 0 ? static_cast<uint32_t>(2 * d) : static_cast<uint32_t>(-2 * d - 1);
}

// Encodes snapshots as one watcher of a session would receive them, decodes
// them with the client library, checks them and writes the vectors.
class VectorWriter {
 public:
  VectorWriter()
      : cache_(std::make_shared<EncodeCache>()),
        encoder_(FieldChoice{true, true, true, true}, cache_) {}

  // The frame for `snap` after `skipped` published frames this watcher did
  // not get. Fails the test (and returns an empty frame) when something is
  // off.
  Frame Add(std::shared_ptr<const SurfaceSnapshot> snap, int64_t skipped, const std::string& kind) {
    std::shared_ptr<const EncodeCache::Result> r = encoder_.EncodeShared(snap);
    const std::string bytes = *r->bytes + FrameTrailer(skipped, kWatcherId);
    Frame f;
    EXPECT_TRUE(f.ParseFromString(bytes)) << kind;
    EXPECT_EQ(f.skipped(), skipped) << kind;
    EXPECT_EQ(f.watcher_id(), kWatcherId) << kind;
    EXPECT_EQ(f.step(), snap->step) << kind;
    const absl::Status applied = client_.Apply(f);
    EXPECT_TRUE(applied.ok()) << kind << " at step " << f.step() << ": " << applied;
    const int64_t n = snap->topology->vertex_count;

    // The watcher's codes: the snapshot quantized on the grid of its last
    // keyframe (what the encoder promises); a delta's zigzags from them.
    std::vector<int64_t> codes(3 * n);
    if (f.has_keyframe()) {
      const QuantizationGrid& g = f.keyframe().grid();
      origin_ = {g.origin().x(), g.origin().y(), g.origin().z()};
      step_ = {g.step().x(), g.step().y(), g.step().z()};
    }
    for (int64_t i = 0; i < 3 * n; ++i) {
      codes[i] = Quantize(origin_[i % 3], step_[i % 3], snap->positions[i]);
      EXPECT_TRUE(codes[i] >= 0 && codes[i] <= 65535) << kind << " coordinate " << i;
    }
    bool escape = false;
    if (f.has_delta() && f.delta().rice_k_size() == 3) {
      for (int64_t v = 0; v < n; ++v) {
        for (int a = 0; a < 3; ++a) {
          const uint32_t z = ZigZag(codes[3 * v + a] - codes_[3 * v + a]);
          escape |= (z >> f.delta().rice_k(a)) >= 16;
        }
      }
    }
    codes_ = codes;

    // Decoded positions: origin + code * step exactly, within the bound of
    // the truth, and the same in the server's own decoder.
    const client::Surface& s = client_.surface();
    EXPECT_EQ(s.vertex_count(), n) << kind;
    EXPECT_EQ(s.quads, snap->topology->quads) << kind;
    double worst = 0;
    for (int64_t i = 0; i < 3 * n && i < static_cast<int64_t>(s.positions.size()); ++i) {
      const int a = static_cast<int>(i % 3);
      EXPECT_EQ(s.positions[i], origin_[a] + codes_[i] * step_[a]) << kind << " coordinate " << i;
      worst = std::max(worst, std::abs(s.positions[i] - snap->positions[i]) / s.error_bound[a]);
    }
    EXPECT_LE(worst, 1.0 + 1e-9) << kind << ": decoded/true difference over the bound";
    EXPECT_EQ(s.displacement.size(), static_cast<size_t>(n)) << kind;
    EXPECT_EQ(s.mass.size(), static_cast<size_t>(n)) << kind;

    // Which kinds this frame shows.
    const bool rice = f.has_delta() && f.delta().rice_k_size() == 3;
    if (f.has_keyframe()) {
      const SurfaceFields& k = f.keyframe().fields();
      if (k.displacement_size() == n && k.strain_size() == n && k.stiffness_size() == n &&
          k.mass_size() == n) {
        seen_.insert("keyframe_all_fields");
      }
      if (frames_ > 0) {
        if (f.keyframe().topology_version() != last_topology_) {
          seen_.insert("keyframe_topology");
        } else if (snap->fields_version != last_fields_version_) {
          seen_.insert("keyframe_fields");
        } else {
          seen_.insert("keyframe_rekey");
        }
      }
    } else {
      const Delta& d = f.delta();
      if (d.moved() == 0 && d.runs_size() == 0) seen_.insert("delta_empty");
      if (d.moved() > 0 && !rice) seen_.insert("delta_fixed");
      if (rice) seen_.insert("delta_rice");
      if (escape) seen_.insert("delta_rice_escape");
      if (skipped > 0) seen_.insert("delta_skipped");
    }
    last_topology_ = s.topology_version;
    last_fields_version_ = snap->fields_version;
    ++frames_;
    last_escape_ = escape;

    // The vectors.
    const uint32_t size = static_cast<uint32_t>(bytes.size());
    for (int b = 0; b < 4; ++b) bin_.push_back(static_cast<char>((size >> (8 * b)) & 0xff));
    bin_ += bytes;
    if (!json_.empty()) json_ += ",\n";
    absl::StrAppend(
        &json_, "{\"kind\": \"", kind, "\", \"step\": ", f.step(), ", \"time\": ", Num(f.time()),
        ", \"keyframe\": ", f.has_keyframe() ? "true" : "false", ", \"skipped\": ", f.skipped(),
        ", \"topology_version\": ", s.topology_version, ", \"vertex_count\": ", s.vertex_count(),
        ",\n \"quads\": ", JsonArray(s.quads), ",\n \"positions\": ", JsonArray(s.positions),
        ",\n \"true_positions\": ", JsonArray(snap->positions), ",\n \"error_bound\": [",
        Num(s.error_bound[0]), ",", Num(s.error_bound[1]), ",", Num(s.error_bound[2]), "]",
        ",\n \"fields\": {\"displacement\": ", JsonArray(s.displacement),
        ", \"strain\": ", JsonArray(s.strain), ", \"stiffness\": ", JsonArray(s.stiffness),
        ", \"mass\": ", JsonArray(s.mass), "},\n \"rice\": ", rice ? "true" : "false",
        ", \"moved\": ", f.has_delta() ? f.delta().moved() : 0, "}");
    return f;
  }

  // Grid of the last keyframe.
  const std::array<double, 3>& grid_step() const { return step_; }
  bool last_escape() const { return last_escape_; }
  const std::set<std::string>& seen() const { return seen_; }
  int frames() const { return frames_; }

  void Write(const std::filesystem::path& dir) const {
    std::filesystem::create_directories(dir);
    std::ofstream bin(dir / "frames.bin", std::ios::binary | std::ios::trunc);
    bin << bin_;
    bin.close();
    EXPECT_TRUE(bin.good()) << "writing " << (dir / "frames.bin");
    std::ofstream json(dir / "expected.json", std::ios::binary | std::ios::trunc);
    json << "[\n" << json_ << "\n]\n";
    json.close();
    EXPECT_TRUE(json.good()) << "writing " << (dir / "expected.json");
  }

 private:
  std::shared_ptr<EncodeCache> cache_;
  SurfaceEncoder encoder_;
  client::SurfaceDecoder client_;
  std::array<double, 3> origin_{}, step_{};
  std::vector<int64_t> codes_;
  std::set<std::string> seen_;
  int64_t last_topology_ = 0;
  int64_t last_fields_version_ = 0;
  int frames_ = 0;
  bool last_escape_ = false;
  std::string bin_, json_;
};

CommandReply Send(SimCore& core, const std::string& text) {
  static uint64_t seq = 0;
  CommandRequest r;
  r.set_client_id("vectors");
  r.set_seq(++seq);
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, r.mutable_command())) << text;
  CommandReply reply;
  core.Process(r, &reply);
  EXPECT_EQ(reply.code(), 0) << text << ": " << reply.message();
  return reply;
}

// A copy of `base` at another step with other positions (moved by hand).
std::shared_ptr<const SurfaceSnapshot> Moved(const SurfaceSnapshot& base, int64_t step, double h,
                                             std::vector<double> positions) {
  auto s = std::make_shared<SurfaceSnapshot>(base);
  s->step = step;
  s->time = step * h;
  s->positions = std::move(positions);
  return s;
}

TEST(SurfaceVectorsTest, EveryKindOfFrameDecodesWithinItsBoundAndIsWrittenOut) {
  CreateSessionRequest create;
  create.set_builtin_scene("block3");
  create.set_levels_override(1);
  absl::StatusOr<SceneRequest> request = ResolveSceneRequest(create);
  ASSERT_TRUE(request.ok()) << request.status();
  BuildLimits limits;
  limits.sim_threads = 1;
  SolidFactory factory = MakeSolidFactory(*request, limits);
  absl::StatusOr<std::shared_ptr<solid::Solid>> solid = factory(nullptr);
  ASSERT_TRUE(solid.ok()) << solid.status();
  SimCore core(*solid, CoreOptions(), /*start_paused=*/true, request->scene, factory);
  const double h = core.solid().time_step();
  VectorWriter w;
  // Steps of frames: the solid's own, or (hand-moved frames) after them.
  int64_t step = 0;
  auto real = [&](int steps) {
    for (int i = 0; i < steps; ++i) EXPECT_TRUE(core.StepOnce().ok());
    step = core.steps();
    return core.MakeSnapshot(true);
  };

  // 1. A painted corner (stiffer and denser): the first keyframe, every field.
  Send(core,
       "paint_material { region { sphere { center { x: 3 y: 3 z: 3 } radius: 1.2 } } "
       "material { young_modulus: 4e5 density: 3000 } strength: 1 }");
  std::shared_ptr<const SurfaceSnapshot> snap = real(0);
  ASSERT_EQ(snap->topology->vertex_count, 218);
  Frame f = w.Add(snap, 0, "keyframe_first");
  ASSERT_TRUE(f.has_keyframe());
  EXPECT_EQ(f.keyframe().fields().mass_size(), 218);

  // 2. A drag pulls the top: deltas of real motion.
  Send(core,
       "drag { material_point { x: 1.5 y: 1.5 z: 3 } target { x: 1.8 y: 1.5 z: 3.6 } "
       "stiffness: 5e4 }");
  for (int k = 0; k < 4; ++k) {
    snap = real(3);
    f = w.Add(snap, 0, "delta");
    EXPECT_TRUE(f.has_delta()) << "real motion " << k;
  }

  // 3. Every vertex 5 codes further on every axis: fixed width (4 bits).
  const std::array<double, 3> gs = w.grid_step();
  std::vector<double> x = snap->positions;
  for (size_t i = 0; i < x.size(); ++i) x[i] += 5 * gs[i % 3];
  std::shared_ptr<const SurfaceSnapshot> hand = Moved(*snap, ++step, h, x);
  f = w.Add(hand, 0, "delta_fixed");
  ASSERT_TRUE(f.has_delta());
  EXPECT_EQ(f.delta().rice_k_size(), 0);
  EXPECT_GE(f.delta().bits(), 1u);
  EXPECT_LE(f.delta().bits(), 4u);
  EXPECT_EQ(f.delta().moved(), 218);

  // 4. One code on y for every third vertex, 3000 on x for the leftmost
  // one: Rice, the outlier escaped (u >= 16).
  size_t left = 0;
  for (size_t v = 0; 3 * v < x.size(); ++v) {
    if (x[3 * v] < x[3 * left]) left = v;
    if (v % 3 == 0) x[3 * v + 1] += gs[1];
  }
  x[3 * left] += 3000 * gs[0];
  hand = Moved(*snap, ++step, h, x);
  f = w.Add(hand, 0, "delta_rice_escape");
  ASSERT_TRUE(f.has_delta());
  EXPECT_EQ(f.delta().rice_k_size(), 3);
  EXPECT_EQ(f.delta().bits(), 0u);
  EXPECT_TRUE(w.last_escape());

  // 5. Nothing moved: an empty delta.
  hand = Moved(*snap, ++step, h, x);
  f = w.Add(hand, 0, "delta_empty");
  ASSERT_TRUE(f.has_delta());
  EXPECT_EQ(f.delta().moved(), 0);
  EXPECT_EQ(f.delta().runs_size(), 0);
  EXPECT_TRUE(f.delta().packed().empty());

  // 6. Back to the solid, 3 published frames later than the last one this
  // watcher got: a delta against that one, skipped = 3.
  snap = real(static_cast<int>(step + 4 - core.steps()));
  f = w.Add(snap, 3, "delta_skipped");
  ASSERT_TRUE(f.has_delta());
  EXPECT_EQ(f.skipped(), 3);
  EXPECT_EQ(f.delta().base_step(), step - 4);

  // 7. A density paint without motion: a keyframe with the new mass field.
  Send(core,
       "paint_material { region { sphere { center { x: 0 y: 0 z: 3 } radius: 1 } } "
       "material { density: 200 } strength: 1 }");
  std::shared_ptr<const SurfaceSnapshot> painted = core.MakeSnapshot(true);
  EXPECT_NE(painted->mass, snap->mass);
  snap = painted;
  f = w.Add(snap, 0, "keyframe_fields");
  ASSERT_TRUE(f.has_keyframe());
  for (int k = 0; k < 2; ++k) {
    snap = real(3);
    f = w.Add(snap, 0, "delta");
    EXPECT_TRUE(f.has_delta());
  }

  // 8. The top vertex 2 m up, out of the grid: a keyframe on a new grid.
  x = snap->positions;
  size_t top = 0;
  for (size_t v = 0; 3 * v < x.size(); ++v) {
    if (x[3 * v + 2] > x[3 * top + 2]) top = v;
  }
  x[3 * top + 2] += 2.0;
  hand = Moved(*snap, ++step, h, x);
  const std::array<double, 3> old_step = w.grid_step();
  f = w.Add(hand, 0, "keyframe_rekey");
  ASSERT_TRUE(f.has_keyframe());
  EXPECT_EQ(f.keyframe().topology_version(), 0);
  EXPECT_GT(w.grid_step()[2], old_step[2]);
  // Back: a delta on the new grid.
  snap = real(static_cast<int>(step + 1 - core.steps()));
  f = w.Add(snap, 0, "delta");
  EXPECT_TRUE(f.has_delta());

  // 9. An extrusion of the side x = 3: a keyframe of the new topology.
  Send(core, "edit { extrude_faces { near { x: 3 y: 1.5 z: 1.5 } distance: 0.5 } }");
  snap = real(1);
  f = w.Add(snap, 0, "keyframe_topology");
  ASSERT_TRUE(f.has_keyframe());
  EXPECT_EQ(f.keyframe().topology_version(), 1);
  EXPECT_NE(f.keyframe().vertex_count(), 218);
  for (int k = 0; k < 2; ++k) {
    snap = real(3);
    f = w.Add(snap, 0, "delta");
    EXPECT_TRUE(f.has_delta());
  }

  // Every kind is there.
  for (const char* kind :
       {"keyframe_all_fields", "delta_fixed", "delta_rice", "delta_rice_escape", "delta_empty",
        "delta_skipped", "keyframe_fields", "keyframe_rekey", "keyframe_topology"}) {
    EXPECT_EQ(w.seen().count(kind), 1u) << "no frame of kind " << kind;
  }
  EXPECT_EQ(w.frames(), 17);

  const char* env = std::getenv("DYNSOLID_VECTORS_DIR");
  const std::filesystem::path dir = env != nullptr && *env != '\0'
                                        ? std::filesystem::path(env)
                                        : std::filesystem::current_path() / "surface_vectors";
  w.Write(dir);
  std::cout << "surface vectors: " << w.frames() << " frames in " << dir << "\n";
  EXPECT_GT(std::filesystem::file_size(dir / "frames.bin"), 0u);
  EXPECT_GT(std::filesystem::file_size(dir / "expected.json"), 0u);
}

}  // namespace
}  // namespace dynsolid::server
