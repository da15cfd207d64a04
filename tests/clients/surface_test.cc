// The client's surface decoder against frames built here by hand from the
// wire format in service.proto (its own small encoder, independent of the
// server's), and the OBJ/.vtu writers.
#include "clients/lib/surface.h"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace dynsolid::client {
namespace {

// Packs values of `bits` bits LSB first, filling bytes from their LSB.
std::string Pack(const std::vector<uint32_t>& values, int bits) {
  std::string out((values.size() * bits + 7) / 8, '\0');
  size_t bit = 0;
  for (uint32_t v : values) {
    for (int b = 0; b < bits; ++b, ++bit) {
      if ((v >> b) & 1u) out[bit / 8] = static_cast<char>(out[bit / 8] | (1 << (bit % 8)));
    }
  }
  return out;
}
// Rice-codes zigzagged values, axis a of each triple with k[a].
std::string RicePack(const std::vector<uint32_t>& values, const std::vector<uint32_t>& k) {
  std::vector<bool> bits;
  auto put = [&](uint32_t v, uint32_t n) {
    for (uint32_t b = 0; b < n; ++b) bits.push_back((v >> b) & 1u);
  };
  for (size_t i = 0; i < values.size(); ++i) {
    const uint32_t z = values[i], kk = k[i % 3];
    const uint32_t u = z >> kk;
    if (u < 16) {
      for (uint32_t j = 0; j < u; ++j) bits.push_back(true);
      bits.push_back(false);
      put(z, kk);
    } else {
      for (int j = 0; j < 16; ++j) bits.push_back(true);
      put(z, 17);
    }
  }
  std::string out((bits.size() + 7) / 8, '\0');
  for (size_t i = 0; i < bits.size(); ++i) {
    if (bits[i]) out[i / 8] = static_cast<char>(out[i / 8] | (1 << (i % 8)));
  }
  return out;
}
uint32_t ZigZag(int32_t d) { return d >= 0 ? 2u * d : static_cast<uint32_t>(-2 * d - 1); }

// A unit square of 4 vertices on the grid origin (1, 2, 3), steps
// (0.5, 0.25, 2), codes given per vertex.
Frame Key(int64_t step, const std::vector<uint16_t>& codes) {
  Frame f;
  f.set_step(step);
  f.set_time(step * 1e-3);
  Keyframe* k = f.mutable_keyframe();
  k->set_topology_version(1);
  k->set_vertex_count(4);
  for (int i : {0, 1, 2, 3}) k->add_quads(i);
  k->mutable_grid()->mutable_origin()->set_x(1);
  k->mutable_grid()->mutable_origin()->set_y(2);
  k->mutable_grid()->mutable_origin()->set_z(3);
  k->mutable_grid()->mutable_step()->set_x(0.5);
  k->mutable_grid()->mutable_step()->set_y(0.25);
  k->mutable_grid()->mutable_step()->set_z(2);
  k->mutable_error_bound()->set_x(0.25);
  k->mutable_error_bound()->set_y(0.125);
  k->mutable_error_bound()->set_z(1);
  std::string bytes;
  for (uint16_t c : codes) {
    bytes.push_back(static_cast<char>(c & 0xff));
    bytes.push_back(static_cast<char>(c >> 8));
  }
  k->set_codes(bytes);
  for (int i = 0; i < 4; ++i) {
    k->add_nodes(100 + i);
    k->mutable_fields()->add_displacement(0.5f * i);
  }
  return f;
}

const std::vector<uint16_t> kCodes = {0, 0, 0, 10, 0, 0, 10, 20, 0, 0, 20, 65535};

TEST(SurfaceDecoderTest, KeyframeDecodesOriginPlusCodeTimesStep) {
  SurfaceDecoder d;
  ASSERT_TRUE(d.Apply(Key(7, kCodes)).ok());
  const Surface& s = d.surface();
  EXPECT_EQ(s.step, 7);
  ASSERT_EQ(s.vertex_count(), 4);
  EXPECT_THAT(s.positions, ::testing::ElementsAre(1, 2, 3, 6, 2, 3, 6, 7, 3, 1, 7, 3 + 65535 * 2.0));
  EXPECT_THAT(s.nodes, ::testing::ElementsAre(100, 101, 102, 103));
  EXPECT_THAT(s.displacement, ::testing::ElementsAre(0, 0.5f, 1, 1.5f));
  EXPECT_EQ(s.error_bound[1], 0.125);
  EXPECT_EQ(s.BoundsMin()[0], 1);
  EXPECT_EQ(s.BoundsMax()[2], 3 + 65535 * 2.0);
}

TEST(SurfaceDecoderTest, DeltaMovesOnlyTheListedVertices) {
  SurfaceDecoder d;
  ASSERT_TRUE(d.Apply(Key(7, kCodes)).ok());
  Frame f;
  f.set_step(9);
  Delta* delta = f.mutable_delta();
  delta->set_base_step(7);
  // Skip 1, take 1 (vertex 1), skip 1, take 1 (vertex 3).
  for (uint32_t r : {1, 1, 1, 1}) delta->add_runs(r);
  delta->set_moved(2);
  // Vertex 1: (+3, -0, +1000); vertex 3: (-1 would underflow x=0? no: +0),
  // (-20 -> y code 0), (-65535 -> z code 0). 17 bits hold zigzag(-65535).
  const std::vector<uint32_t> z = {ZigZag(3), ZigZag(0), ZigZag(1000),
                                   ZigZag(0), ZigZag(-20), ZigZag(-65535)};
  delta->set_bits(17);
  delta->set_packed(Pack(z, 17));
  delta->mutable_fields()->add_displacement(9);
  delta->mutable_fields()->add_displacement(8);
  ASSERT_TRUE(d.Apply(f).ok());
  const Surface& s = d.surface();
  EXPECT_EQ(s.step, 9);
  EXPECT_THAT(s.positions,
              ::testing::ElementsAre(1, 2, 3, 1 + 13 * 0.5, 2, 3 + 1000 * 2.0, 6, 7, 3, 1, 2, 3));
  EXPECT_THAT(s.displacement, ::testing::ElementsAre(0, 9, 1, 8));

  // An empty delta (nothing moved) only advances the step.
  Frame still;
  still.set_step(10);
  still.mutable_delta()->set_base_step(9);
  ASSERT_TRUE(d.Apply(still).ok());
  EXPECT_EQ(d.step(), 10);
  EXPECT_EQ(d.surface().positions[3], 1 + 13 * 0.5);
}

TEST(SurfaceDecoderTest, MassFieldComesWithKeyframesAndListedVerticesAndGoesIntoTheVtu) {
  SurfaceDecoder d;
  Frame key = Key(7, kCodes);
  for (float m : {100.f, 200.f, 300.f, 400.f})
    key.mutable_keyframe()->mutable_fields()->add_mass(m);
  ASSERT_TRUE(d.Apply(key).ok());
  EXPECT_THAT(d.surface().mass, ::testing::ElementsAre(100, 200, 300, 400));
  Frame f;
  f.set_step(8);
  Delta* delta = f.mutable_delta();
  delta->set_base_step(7);
  for (uint32_t r : {2, 1}) delta->add_runs(r);  // vertex 2 only
  delta->set_moved(1);
  delta->set_bits(2);
  delta->set_packed(Pack({ZigZag(1), ZigZag(0), ZigZag(0)}, 2));
  delta->mutable_fields()->add_mass(950);
  delta->mutable_fields()->add_displacement(4);
  ASSERT_TRUE(d.Apply(f).ok());
  EXPECT_THAT(d.surface().mass, ::testing::ElementsAre(100, 200, 950, 400));
  EXPECT_THAT(d.surface().displacement, ::testing::ElementsAre(0, 0.5f, 4, 1.5f));
  // Wrong counts, or mass in a delta when the keyframe had none: refused.
  f.set_step(9);
  delta->set_base_step(8);
  delta->mutable_fields()->add_mass(1);
  EXPECT_EQ(d.Apply(f).message(), "delta.fields.mass: 2 values for 1 vertices");
  SurfaceDecoder no_mass;
  ASSERT_TRUE(no_mass.Apply(Key(8, kCodes)).ok());
  delta->mutable_fields()->clear_mass();
  delta->mutable_fields()->add_mass(1);
  EXPECT_EQ(no_mass.Apply(f).message(), "delta.fields.mass: present but the keyframe had none");
  Frame short_key = Key(7, kCodes);
  short_key.mutable_keyframe()->mutable_fields()->add_mass(5);
  EXPECT_EQ(no_mass.Apply(short_key).message(), "keyframe.fields.mass: 1 values for 4 vertices");
  const std::string path = ::testing::TempDir() + "/mass.vtu";
  ASSERT_TRUE(WriteVtu(d.surface(), path).ok());
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_THAT(text.str(),
              ::testing::HasSubstr("<DataArray type=\"Float32\" Name=\"mass\" format=\"ascii\">\n"
                                   "100\n200\n950\n400\n</DataArray>"));
}

TEST(SurfaceDecoderTest, SmallBitWidthsRoundTrip) {
  for (int bits = 2; bits <= 17; ++bits) {
    SurfaceDecoder d;
    ASSERT_TRUE(d.Apply(Key(0, std::vector<uint16_t>(12, 30000))).ok());
    Frame f;
    f.set_step(1);
    f.mutable_delta()->set_base_step(0);
    f.mutable_delta()->add_runs(0);
    f.mutable_delta()->add_runs(4);
    f.mutable_delta()->set_moved(4);
    f.mutable_delta()->set_bits(bits);
    // The largest |d| that fits (and keeps codes around 30000 in range).
    const int32_t big = std::min((1 << (bits - 1)) - 1, 30000);
    std::vector<int32_t> diffs;
    std::vector<uint32_t> zz;
    for (int i = 0; i < 12; ++i) {
      const int32_t v = (i % 2 == 0 ? 1 : -1) * ((i * 7919) % (big + 1));
      diffs.push_back(v);
      zz.push_back(ZigZag(v));
    }
    f.mutable_delta()->set_packed(Pack(zz, bits));
    ASSERT_TRUE(d.Apply(f).ok()) << bits;
    const double steps[3] = {0.5, 0.25, 2};
    const double origin[3] = {1, 2, 3};
    for (int i = 0; i < 12; ++i) {
      EXPECT_EQ(d.surface().positions[i], origin[i % 3] + (30000 + diffs[i]) * steps[i % 3])
          << "bits " << bits << " value " << i;
    }
  }
}

TEST(SurfaceDecoderTest, RiceCodedDeltasDecodeIncludingEscapes) {
  // k = 0 on x (every value unary or escaped), 3 on y, 16 on z (never
  // escaped: u = z >> 16 <= 1).
  const std::vector<uint32_t> k = {0, 3, 16};
  const std::vector<int32_t> diffs = {0,  5,   -30000, 7,    -1,  12000,
                                      -8, 200, 1,      3000, -64, -29999};
  {
    const int vertices_listed = 4;
    SurfaceDecoder d;
    ASSERT_TRUE(d.Apply(Key(0, std::vector<uint16_t>(12, 30000))).ok());
    Frame f;
    f.set_step(1);
    Delta* delta = f.mutable_delta();
    delta->set_base_step(0);
    delta->add_runs(0);
    delta->add_runs(vertices_listed);
    delta->set_moved(vertices_listed);
    for (uint32_t kk : k) delta->add_rice_k(kk);
    std::vector<uint32_t> zz;
    for (int32_t v : diffs) zz.push_back(ZigZag(v));
    delta->set_packed(RicePack(zz, k));
    ASSERT_TRUE(d.Apply(f).ok()) << d.Apply(f).message();
    const double steps[3] = {0.5, 0.25, 2};
    const double origin[3] = {1, 2, 3};
    for (int i = 0; i < 12; ++i) {
      EXPECT_EQ(d.surface().positions[i], origin[i % 3] + (30000 + diffs[i]) * steps[i % 3])
          << "value " << i;
    }
    // Truncated, padded, or malformed parameters: rejected, nothing changes.
    SurfaceDecoder fresh;
    ASSERT_TRUE(fresh.Apply(Key(0, std::vector<uint16_t>(12, 30000))).ok());
    const std::vector<double> before = fresh.surface().positions;
    Frame bad = f;
    bad.mutable_delta()->set_packed(f.delta().packed().substr(0, f.delta().packed().size() - 2));
    EXPECT_EQ(fresh.Apply(bad).code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(fresh.Apply(bad).message()),
                ::testing::MatchesRegex("delta.packed: [0-9]+ bytes end inside vertex 3 axis [0-2] "
                                        "\\(4 vertices listed\\)"));
    bad.mutable_delta()->set_packed(f.delta().packed() + std::string(1, '\0'));
    EXPECT_THAT(std::string(fresh.Apply(bad).message()),
                ::testing::MatchesRegex("delta.packed: [0-9]+ bytes, the Rice codes take [0-9]+"));
    bad.mutable_delta()->set_packed(f.delta().packed());
    bad.mutable_delta()->set_rice_k(1, 17);
    EXPECT_EQ(fresh.Apply(bad).message(), "delta.rice_k[1]: 17 outside [0, 16]");
    bad.mutable_delta()->clear_rice_k();
    bad.mutable_delta()->add_rice_k(1);
    EXPECT_EQ(fresh.Apply(bad).message(), "delta.rice_k: 1 values, expected 3 (x, y, z)");
    EXPECT_EQ(fresh.surface().positions, before);
    EXPECT_EQ(fresh.step(), 0);
  }
}

TEST(SurfaceDecoderTest, BadFramesAreRejectedAndChangeNothing) {
  SurfaceDecoder d;
  Frame delta;
  delta.set_step(3);
  delta.mutable_delta()->set_base_step(0);
  absl::Status s = d.Apply(delta);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(s.message(), "delta at step 3 before any keyframe");

  ASSERT_TRUE(d.Apply(Key(7, kCodes)).ok());
  const std::vector<double> before = d.surface().positions;
  auto expect_unchanged = [&] {
    EXPECT_EQ(d.step(), 7);
    EXPECT_EQ(d.surface().positions, before);
  };

  delta.mutable_delta()->set_base_step(6);
  s = d.Apply(delta);
  EXPECT_EQ(s.message(), "delta at step 3: base_step 6 but the last frame was step 7");
  expect_unchanged();

  Frame bad;
  bad.set_step(8);
  Delta* b = bad.mutable_delta();
  b->set_base_step(7);
  b->add_runs(3);
  b->add_runs(2);
  b->set_moved(1);
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.runs: run 1 ends at vertex 5, past the 4 vertices");
  expect_unchanged();

  b->clear_runs();
  b->add_runs(0);
  b->add_runs(1);
  b->set_moved(2);
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.moved: 2 but runs list 1 vertices");
  b->set_moved(1);
  b->set_bits(4);
  b->set_packed(std::string(1, '\0'));
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.packed: 1 bytes, expected 2 for 1 vertices at 4 bits");
  b->set_bits(18);
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.bits: 18 outside [1, 17]");
  // Vertex 0 has code 0 on x: -1 leaves the grid.
  b->set_bits(4);
  b->set_packed(Pack({ZigZag(-1), 0, 0}, 4));
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.packed: vertex 0 axis 0 code -1 outside [0, 65535]");
  b->set_packed(Pack({0, 0, 0}, 4));
  b->mutable_fields()->add_strain(1);
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.fields.strain: present but the keyframe had none");
  b->mutable_fields()->clear_strain();
  b->mutable_fields()->add_displacement(1);
  b->mutable_fields()->add_displacement(2);
  s = d.Apply(bad);
  EXPECT_EQ(s.message(), "delta.fields.displacement: 2 values for 1 vertices");
  expect_unchanged();

  Frame k = Key(9, kCodes);
  k.mutable_keyframe()->set_codes("abc");
  s = d.Apply(k);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "keyframe.codes: 3 bytes for 4 vertices (6 each)");
  k = Key(9, kCodes);
  k.mutable_keyframe()->set_quads(2, 4);
  EXPECT_EQ(d.Apply(k).message(), "keyframe.quads[2]: vertex 4 outside [0, 4)");
  k = Key(9, kCodes);
  k.mutable_keyframe()->mutable_grid()->mutable_step()->set_y(0);
  EXPECT_EQ(d.Apply(k).message(),
            "keyframe.grid: origin 2 / step 0 on axis 1 (steps must be finite and > 0)");
  expect_unchanged();
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(SurfaceWriterTest, ObjAndVtuHoldThePositionsAndQuads) {
  SurfaceDecoder d;
  ASSERT_TRUE(d.Apply(Key(7, kCodes)).ok());
  const std::string dir = ::testing::TempDir();
  ASSERT_TRUE(WriteObj(d.surface(), dir + "/s.obj").ok());
  EXPECT_EQ(ReadAll(dir + "/s.obj"),
            "# dynsolid surface, step 7, time 0.007 s, 4 vertices, 1 quads\n"
            "v 1 2 3\nv 6 2 3\nv 6 7 3\nv 1 7 131073\nf 1 2 3 4\n");
  ASSERT_TRUE(WriteVtu(d.surface(), dir + "/s.vtu").ok());
  const std::string vtu = ReadAll(dir + "/s.vtu");
  EXPECT_THAT(vtu, ::testing::HasSubstr("<Piece NumberOfPoints=\"4\" NumberOfCells=\"1\">"));
  EXPECT_THAT(vtu, ::testing::HasSubstr(
                       "<DataArray type=\"Float32\" Name=\"displacement\" format=\"ascii\">\n"
                       "0\n0.5\n1\n1.5\n</DataArray>"));
  EXPECT_THAT(vtu, ::testing::HasSubstr("1 2 3\n6 2 3\n6 7 3\n1 7 131073\n</DataArray>"));
  EXPECT_THAT(vtu, ::testing::HasSubstr("Name=\"connectivity\" format=\"ascii\">\n0 1 2 3\n"));
  EXPECT_THAT(vtu, ::testing::HasSubstr("Name=\"types\" format=\"ascii\">\n9\n"));
  EXPECT_FALSE(WriteObj(d.surface(), dir + "/no/such/dir/s.obj").ok());
}

}  // namespace
}  // namespace dynsolid::client
