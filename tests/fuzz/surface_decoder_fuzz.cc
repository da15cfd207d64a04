// Fuzzes the C++ decoder of the Watch stream's surface frames
// (service.proto Frame: keyframes and quantized deltas): the client
// library's client::SurfaceDecoder (clients/lib/surface.h), the one
// dynsolid-client, the benchmarks and the server's tests run on frames.
//
// Input: 2-byte-length-prefixed chunks (fuzz_util.h), each parsed as a
// Frame and applied, in order. Seeds are real streams
// from server::SurfaceEncoder (a keyframe, deltas, fields, a new keyframe).
//
// Invariants: no crash or sanitizer report; the client decoder changes
// nothing when it refuses a frame (its header promises so); after a frame
// it accepts, its surface is consistent (3 coordinates per vertex, quads
// name vertices, each field empty or one value per vertex).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "clients/lib/surface.h"
#include "server/surface_codec.h"
#include "tests/fuzz/fuzz_proto.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace fz = dynsolid::fuzz;
using dynsolid::Frame;

bool SameSurface(const dynsolid::client::Surface& a, const dynsolid::client::Surface& b) {
  auto same_bits = [](const auto& x, const auto& y) {
    return x.size() == y.size() &&
           (x.empty() || std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0);
  };
  return a.step == b.step && a.topology_version == b.topology_version &&
         std::memcmp(&a.time, &b.time, sizeof(double)) == 0 && same_bits(a.positions, b.positions) &&
         a.quads == b.quads && a.nodes == b.nodes && same_bits(a.displacement, b.displacement) &&
         same_bits(a.strain, b.strain) && same_bits(a.stiffness, b.stiffness) &&
         same_bits(a.mass, b.mass);
}

// A stream from the server's encoder: a 2x2 grid of quads on a bumpy
// sheet (9 vertices), moved a little each frame, then far (a new keyframe).
std::vector<std::string> SeedStream(bool fields) {
  auto topology = std::make_shared<dynsolid::server::SurfaceTopology>();
  topology->version = 1;
  topology->vertex_count = 9;
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const int v = 3 * j + i;
      topology->quads.insert(topology->quads.end(), {v, v + 1, v + 4, v + 3});
    }
  }
  for (int v = 0; v < 9; ++v) topology->nodes.push_back(10 + v);
  dynsolid::server::FieldChoice choice;
  choice.displacement = choice.strain = choice.stiffness = choice.mass = fields;
  dynsolid::server::SurfaceEncoder encoder(choice);
  std::vector<std::string> frames;
  for (int k = 0; k < 5; ++k) {
    auto s = std::make_shared<dynsolid::server::SurfaceSnapshot>();
    s->step = 10 * k;
    s->time = 1e-3 * s->step;
    s->topology = topology;
    const double shift = k == 4 ? 5.0 : 0.0;
    for (int v = 0; v < 9; ++v) {
      // Only some vertices move between frames, so deltas have runs.
      const double wiggle = (v % 3 == 1) ? 0.01 * k : 0.0;
      s->positions.insert(s->positions.end(),
                          {0.5 * (v % 3) + shift, 0.5 * (v / 3), 0.1 * (v % 2) + wiggle});
      if (fields) {
        s->displacement.push_back(static_cast<float>(wiggle));
        s->strain.push_back(0.001f * v);
        s->stiffness.push_back(1e5f);
        s->mass.push_back(0.125f);
      }
    }
    Frame frame;
    encoder.Encode(s, &frame);
    frames.push_back(frame.SerializeAsString());
  }
  return frames;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  dynsolid::fuzz::QuietProtobuf();
  const std::string dir = fz::SeedDir();
  if (!dir.empty()) {
    fz::WriteFile(dir + "/stream_positions", fz::JoinChunks(SeedStream(false)));
    fz::WriteFile(dir + "/stream_fields", fz::JoinChunks(SeedStream(true)));
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  dynsolid::client::SurfaceDecoder client;
  for (std::string_view chunk :
       fz::SplitChunks(std::string_view(reinterpret_cast<const char*>(data), size))) {
    Frame frame;
    if (!frame.ParseFromArray(chunk.data(), static_cast<int>(chunk.size()))) continue;

    const dynsolid::client::Surface before = client.surface();
    const bool had_keyframe = client.has_keyframe();
    const absl::Status c = client.Apply(frame);
    const dynsolid::client::Surface& s = client.surface();
    if (!c.ok()) {
      FUZZ_CHECK(SameSurface(before, s) && had_keyframe == client.has_keyframe(),
                 "client decoder: a refused frame changed the surface (%s)",
                 std::string(c.message()).c_str());
    } else {
      const size_t n = s.positions.size() / 3;
      FUZZ_CHECK(s.positions.size() == 3 * n, "client decoder: %zu coordinates",
                 s.positions.size());
      FUZZ_CHECK(s.quads.size() % 4 == 0, "client decoder: %zu quad indices", s.quads.size());
      for (int32_t q : s.quads) {
        FUZZ_CHECK(q >= 0 && static_cast<size_t>(q) < n, "client decoder: quad vertex %d of %zu",
                   q, n);
      }
      for (const std::vector<float>* f : {&s.displacement, &s.strain, &s.stiffness, &s.mass}) {
        FUZZ_CHECK(f->empty() || f->size() == n, "client decoder: a field of %zu values for %zu",
                   f->size(), n);
      }
      FUZZ_CHECK(s.nodes.empty() || s.nodes.size() == n, "client decoder: %zu nodes for %zu",
                 s.nodes.size(), n);
    }
  }
  return 0;
}
