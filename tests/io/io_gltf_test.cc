// Tests of the glTF binary (.glb) writer: the GLB header and chunks, the
// JSON (parsed here), accessors, buffer views and the BIN data read back
// byte by byte; and every file checked by the Khronos glTF validator (npm
// gltf-validator, tests/io/gltf/validate.mjs, installed by `npm ci` there).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "solver/io/gltf_writer.h"
#include "tests/io/export_surfaces.h"
#include "tests/io/io_test_util.h"
#include "tests/io/mini_json.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::io {
namespace {

using ::dynsolid::testing::StatusIs;
using testing::F32At;
using ::testing::HasSubstr;
using testing::Json;
using testing::ReadTextFile;
using testing::ScopedTempDir;
using testing::U32At;

constexpr int kFloat = 5126;
constexpr int kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;

// A .glb read back: its JSON (parsed) and BIN chunk, after the layout
// checks of the GLB container (header, chunk types, lengths, padding).
struct Glb {
  Json json;
  std::string bin;
};

std::optional<Glb> ReadGlb(const std::string& bytes) {
  if (bytes.size() < 28) {
    ADD_FAILURE() << "GLB of " << bytes.size() << " bytes";
    return std::nullopt;
  }
  EXPECT_EQ(bytes.substr(0, 4), "glTF") << "magic";
  EXPECT_EQ(U32At(bytes, 4), 2u) << "GLB version";
  EXPECT_EQ(U32At(bytes, 8), bytes.size()) << "header length is the file's";
  EXPECT_EQ(bytes.size() % 4, 0u) << "GLB length aligned to 4";
  const uint32_t json_length = U32At(bytes, 12);
  EXPECT_EQ(bytes.substr(16, 4), "JSON") << "first chunk type";
  EXPECT_EQ(json_length % 4, 0u) << "JSON chunk padded to 4 bytes";
  if (20 + static_cast<size_t>(json_length) + 8 > bytes.size()) {
    ADD_FAILURE() << "JSON chunk of " << json_length << " bytes overruns the file";
    return std::nullopt;
  }
  const std::string json_text = bytes.substr(20, json_length);
  const size_t bin_at = 20 + json_length;
  const uint32_t bin_length = U32At(bytes, bin_at);
  EXPECT_EQ(bytes.substr(bin_at + 4, 4), std::string("BIN\0", 4)) << "second chunk type";
  EXPECT_EQ(bin_length % 4, 0u) << "BIN chunk padded to 4 bytes";
  EXPECT_EQ(bin_at + 8 + static_cast<size_t>(bin_length), bytes.size())
      << "the BIN chunk ends the file";
  testing::JsonParser parser;
  std::optional<Json> json = parser.Parse(json_text);
  if (!json) {
    ADD_FAILURE() << "JSON chunk does not parse: " << parser.error() << "\n" << json_text;
    return std::nullopt;
  }
  const size_t end = json_text.find_last_not_of(' ');
  EXPECT_EQ(json_text[end], '}') << "only spaces pad the JSON chunk";
  Glb glb;
  glb.json = *std::move(json);
  glb.bin = bytes.substr(bin_at + 8, std::min<size_t>(bin_length, bytes.size() - bin_at - 8));
  return glb;
}

// Checks accessor `a` (componentType, type, count) and its buffer view,
// and returns the view's byte offset into the BIN chunk.
size_t CheckAccessor(const Glb& glb, int a, int component_type, const std::string& type,
                     int64_t count, int target) {
  const Json& acc = glb.json["accessors"][a];
  EXPECT_EQ(acc["componentType"].number, component_type) << "accessor " << a;
  EXPECT_EQ(acc["type"].text, type) << "accessor " << a;
  EXPECT_EQ(acc["count"].number, count) << "accessor " << a;
  const Json& view = glb.json["bufferViews"][static_cast<size_t>(acc["bufferView"].number)];
  const size_t offset = static_cast<size_t>(view["byteOffset"].number);
  const size_t length = static_cast<size_t>(view["byteLength"].number);
  const size_t element = type == "VEC3" ? 12 : 4;
  EXPECT_EQ(view["buffer"].number, 0) << "accessor " << a;
  EXPECT_EQ(view["target"].number, target) << "accessor " << a << "'s buffer view target";
  EXPECT_EQ(offset % 4, 0u) << "accessor " << a << "'s buffer view offset aligned to 4";
  EXPECT_EQ(length % 4, 0u) << "accessor " << a << "'s buffer view length aligned to 4";
  EXPECT_EQ(length, element * static_cast<size_t>(count)) << "accessor " << a;
  EXPECT_LE(offset + length, glb.bin.size()) << "accessor " << a << " within the BIN chunk";
  return offset;
}

// Everything the glTF must say about `s`; returns the COLOR_0 values (empty
// without colours) for the caller to check.
std::vector<Eigen::Vector3d> CheckGlbMatchesSurface(const Glb& glb, const mesh::BoundarySurface& s,
                                                    const Eigen::Vector3d& centre, bool colours) {
  const Json& j = glb.json;
  EXPECT_EQ(j["asset"]["version"].text, "2.0");
  EXPECT_EQ(j["asset"]["generator"].text, "dynsolid");
  EXPECT_EQ(j["scene"].number, 0);
  EXPECT_EQ(j["scenes"][0]["nodes"][0].number, 0);
  EXPECT_EQ(j["nodes"][0]["mesh"].number, 0);
  const Json& rotation = j["nodes"][0]["rotation"];
  EXPECT_NEAR(rotation[0].number, -std::sqrt(0.5), 1e-15) << "z-up to y-up about x";
  EXPECT_NEAR(rotation[3].number, std::sqrt(0.5), 1e-15);
  EXPECT_EQ(j["buffers"].size(), 1u);
  EXPECT_EQ(j["buffers"][0]["byteLength"].number, glb.bin.size());
  EXPECT_EQ(j["meshes"].size(), 1u);
  EXPECT_EQ(j["meshes"][0]["primitives"].size(), 1u);
  const Json& prim = j["meshes"][0]["primitives"][0];
  EXPECT_EQ(prim["mode"].number, 4) << "TRIANGLES";
  const Json& attributes = prim["attributes"];
  EXPECT_EQ(attributes.size(), colours ? 3u : 2u);
  EXPECT_EQ(attributes.Has("COLOR_0"), colours);
  const int64_t nv = s.positions.rows();
  const int64_t nt = testing::FanTriangles(s);

  // POSITION: the surface's vertices in float32, min and max exact.
  const int pa = static_cast<int>(attributes["POSITION"].number);
  const size_t p_at = CheckAccessor(glb, pa, kFloat, "VEC3", nv, kArrayBuffer);
  std::vector<Eigen::Vector3d> positions;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (int64_t i = 0; i < nv; ++i) {
    positions.push_back(testing::Vec3At(glb.bin, p_at + 12 * i));
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(positions[i][k], static_cast<float>(s.positions(i, k)))
          << "vertex " << i << " coordinate " << k;
    }
    lo = lo.cwiseMin(positions[i]);
    hi = hi.cwiseMax(positions[i]);
  }
  const Json& acc = j["accessors"][pa];
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(acc["min"][k].number, lo[k]) << "POSITION min " << k;
    EXPECT_EQ(acc["max"][k].number, hi[k]) << "POSITION max " << k;
  }

  // indices: the loops' fans in face order.
  const int ia = static_cast<int>(prim["indices"].number);
  const size_t i_at = CheckAccessor(glb, ia, kUnsignedInt, "SCALAR", 3 * nt, kElementArrayBuffer);
  std::vector<uint32_t> indices;
  for (int64_t i = 0; i < 3 * nt; ++i) indices.push_back(U32At(glb.bin, i_at + 4 * i));
  std::vector<uint32_t> fans;
  for (int32_t f = 0; f < s.faces.rows(); ++f) {
    const auto loop = s.faces.row(f);
    for (size_t i = 1; i + 1 < loop.size(); ++i) {
      fans.insert(fans.end(), {static_cast<uint32_t>(loop[0]), static_cast<uint32_t>(loop[i]),
                               static_cast<uint32_t>(loop[i + 1])});
    }
  }
  EXPECT_EQ(indices, fans);

  // NORMAL: unit, outward (the surfaces here are convex), and the
  // normalized sum of the vertex's triangles' area vectors.
  const int na = static_cast<int>(attributes["NORMAL"].number);
  const size_t n_at = CheckAccessor(glb, na, kFloat, "VEC3", nv, kArrayBuffer);
  std::vector<Eigen::Vector3d> area(nv, Eigen::Vector3d::Zero());
  double six_v = 0.0;
  for (int64_t t = 0; t < nt; ++t) {
    const Eigen::Vector3d& a = positions[indices[3 * t]];
    const Eigen::Vector3d& b = positions[indices[3 * t + 1]];
    const Eigen::Vector3d& c = positions[indices[3 * t + 2]];
    for (int k = 0; k < 3; ++k) area[indices[3 * t + k]] += (b - a).cross(c - a);
    six_v += a.dot(b.cross(c));
  }
  EXPECT_NEAR(six_v / 6.0, testing::FanVolume(s), 1e-5 * testing::FanVolume(s))
      << "volume enclosed by the glTF's triangles";
  for (int64_t i = 0; i < nv; ++i) {
    const Eigen::Vector3d n = testing::Vec3At(glb.bin, n_at + 12 * i);
    EXPECT_NEAR(n.norm(), 1.0, 1e-6) << "normal of vertex " << i;
    EXPECT_GT(n.dot(positions[i] - centre), 0.0) << "normal of vertex " << i << " points inward";
    EXPECT_GT(n.dot(area[i].normalized()), 1.0 - 1e-5) << "normal of vertex " << i;
  }

  std::vector<Eigen::Vector3d> colour_values;
  if (colours) {
    const int ca = static_cast<int>(attributes["COLOR_0"].number);
    const size_t c_at = CheckAccessor(glb, ca, kFloat, "VEC3", nv, kArrayBuffer);
    for (int64_t i = 0; i < nv; ++i)
      colour_values.push_back(testing::Vec3At(glb.bin, c_at + 12 * i));
  }
  // Buffer views do not overlap.
  std::vector<std::pair<double, double>> views;
  for (const Json& v : j["bufferViews"].items) {
    views.push_back({v["byteOffset"].number, v["byteOffset"].number + v["byteLength"].number});
  }
  std::sort(views.begin(), views.end());
  for (size_t v = 1; v < views.size(); ++v) EXPECT_LE(views[v - 1].second, views[v].first);
  return colour_values;
}

// Runs the Khronos validator on `file`; fails the test when it is not
// installed or reports errors or warnings.
void ExpectValidGltf(const std::string& file) {
  const std::string dir = testing::SourceDir() + "/tests/io/gltf";
  if (!std::filesystem::exists(dir + "/node_modules/gltf-validator/package.json")) {
    ADD_FAILURE() << "the glTF validator is not installed: run `npm ci` in " << dir
                  << " (scripts/setup_web.sh does)";
    return;
  }
  const testing::CommandResult r =
      testing::RunCommand("node '" + dir + "/validate.mjs' '" + file + "'");
  EXPECT_EQ(r.exit_code, 0) << "glTF validator on " << file << ":\n" << r.output;
  EXPECT_THAT(r.output, HasSubstr(": 0 errors, 0 warnings,")) << r.output;
  const size_t summary = r.output.rfind("validate.mjs: ");
  if (summary != std::string::npos) std::cout << r.output.substr(summary);
}

TEST(GltfWriterTest, CubeLayoutAccessorsAndValidator) {
  const mesh::BoundarySurface cube = testing::CubeSurface(2.0);
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/cube.glb";
  ASSERT_OK(WriteGlb(path, cube));
  const std::string bytes = ReadTextFile(path);
  std::string in_memory = "prefix";
  ASSERT_OK(GlbBytes(cube, {}, &in_memory));
  EXPECT_TRUE(in_memory == "prefix" + bytes) << "GlbBytes appends the file's bytes";

  const std::optional<Glb> glb = ReadGlb(bytes);
  ASSERT_TRUE(glb.has_value());
  CheckGlbMatchesSurface(*glb, cube, Eigen::Vector3d(1, 1, 1), /*colours=*/false);
  const Json& acc = glb->json["accessors"];
  EXPECT_EQ(acc[0]["count"].number, 8) << "8 vertices";
  EXPECT_EQ(acc[2]["count"].number, 36) << "12 triangles";
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(acc[0]["min"][k].number, 0.0);
    EXPECT_EQ(acc[0]["max"][k].number, 2.0);
  }
  ExpectValidGltf(path);
}

TEST(GltfWriterTest, SubdividedBlockColouredByAFieldAndValidator) {
  testing::SubdividedBlock block = testing::SubdividedBlockSurface(2);
  mesh::BoundarySurface& s = block.surface;
  testing::AddFields(s);
  ScopedTempDir tmp;
  for (const std::string field : {"height", "offset"}) {
    SCOPED_TRACE(field);
    const std::string path = tmp.path() + "/block_" + field + ".glb";
    ASSERT_OK(WriteGlb(path, s, {.color_field = field}));
    const std::optional<Glb> glb = ReadGlb(ReadTextFile(path));
    ASSERT_TRUE(glb.has_value());
    const std::vector<Eigen::Vector3d> colours =
        CheckGlbMatchesSurface(*glb, s, Eigen::Vector3d(1, 1, 1), /*colours=*/true);
    ASSERT_EQ(static_cast<int64_t>(colours.size()), s.positions.rows());
    // The scalar per vertex: the value, or the offset's magnitude.
    const mesh::VertexField& f = s.fields[field == "height" ? 0 : 1];
    std::vector<double> scalar;
    for (int64_t i = 0; i < s.positions.rows(); ++i) {
      scalar.push_back(
          f.components == 1
              ? f.values[i]
              : Eigen::Vector3d(f.values[3 * i], f.values[3 * i + 1], f.values[3 * i + 2]).norm());
    }
    const double lo = *std::min_element(scalar.begin(), scalar.end());
    const double hi = *std::max_element(scalar.begin(), scalar.end());
    ASSERT_LT(lo, hi);
    const Json& extras = glb->json["meshes"][0]["extras"];
    EXPECT_EQ(extras["color_field"].text, field);
    EXPECT_EQ(extras["colormap"].text, "viridis");
    EXPECT_NEAR(extras["color_range"][0].number, lo, 1e-15 * std::abs(hi));
    EXPECT_NEAR(extras["color_range"][1].number, hi, 1e-15 * std::abs(hi));
    bool saw_low = false, saw_high = false;
    for (int64_t i = 0; i < s.positions.rows(); ++i) {
      const std::array<float, 3> want = ViridisLinearRgb((scalar[i] - lo) / (hi - lo));
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(colours[i][k], want[k], 1e-6) << "vertex " << i;
        EXPECT_GE(colours[i][k], 0.0);
        EXPECT_LE(colours[i][k], 1.0);
      }
      saw_low |= colours[i] == Eigen::Vector3d(want[0], want[1], want[2]) && scalar[i] == lo;
      saw_high |= scalar[i] == hi && std::abs(colours[i][1] - ViridisLinearRgb(1.0)[1]) < 1e-7;
    }
    EXPECT_TRUE(saw_low) << "the field's minimum takes viridis' first colour";
    EXPECT_TRUE(saw_high) << "the field's maximum takes viridis' last colour";
    ExpectValidGltf(path);
  }
}

TEST(GltfWriterTest, ViridisEndsAndFlatField) {
  // sRGB 0.267 0.005 0.329 (dark purple) and 0.993 0.906 0.144 (yellow), as linear.
  const std::array<float, 3> low = ViridisLinearRgb(0.0);
  const std::array<float, 3> high = ViridisLinearRgb(1.0);
  EXPECT_NEAR(low[0], std::pow((0.267 + 0.055) / 1.055, 2.4), 1e-6);
  EXPECT_NEAR(low[1], 0.005 / 12.92, 1e-7);
  EXPECT_NEAR(high[0], std::pow((0.993 + 0.055) / 1.055, 2.4), 1e-6);
  EXPECT_EQ(ViridisLinearRgb(-3.0), low) << "clamped";
  EXPECT_EQ(ViridisLinearRgb(std::numeric_limits<double>::quiet_NaN()), low);
  EXPECT_EQ(ViridisLinearRgb(7.0), high) << "clamped";

  mesh::BoundarySurface cube = testing::CubeSurface(1.0);
  cube.fields.push_back({"stiffness", 1, std::vector<double>(8, 1e7)});
  std::string bytes;
  ASSERT_OK(GlbBytes(cube, {.color_field = "stiffness"}, &bytes));
  const std::optional<Glb> glb = ReadGlb(bytes);
  ASSERT_TRUE(glb.has_value());
  const std::vector<Eigen::Vector3d> colours =
      CheckGlbMatchesSurface(*glb, cube, Eigen::Vector3d(0.5, 0.5, 0.5), true);
  const std::array<float, 3> middle = ViridisLinearRgb(0.5);
  for (const Eigen::Vector3d& c : colours) {
    EXPECT_EQ(c, Eigen::Vector3d(middle[0], middle[1], middle[2])) << "a flat field is the middle";
  }
}

// Bad surfaces and options: refused with a message naming the vertex, face
// or field; no file written, nothing appended.
TEST(GltfWriterTest, RefusesBadSurfaces) {
  struct Case {
    std::string what;
    mesh::BoundarySurface surface;
    GlbOptions options;
    std::string message;
  };
  std::vector<Case> cases;
  mesh::BoundarySurface cube = testing::CubeSurface(1.0);
  cube.fields.push_back({"strain", 1, std::vector<double>(8, 0.5)});
  {
    mesh::BoundarySurface s = cube;
    s.positions(5, 0) = std::numeric_limits<double>::quiet_NaN();
    cases.push_back({"nan", s, {}, "surface vertex 5 has a non-finite coordinate x (nan)"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.faces.items[s.faces.offsets[2] + 3] = 12;
    cases.push_back({"index", s, {}, "surface face 2 refers to vertex 12: expected 0 to 7"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.faces = mesh::Csr{};
    cases.push_back({"no faces", s, {}, "surface has no faces (8 vertices)"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.positions(1, 2) = -1e40;
    cases.push_back(
        {"float32", s, {}, "surface vertex 1 has coordinate z = -1e+40, beyond float32"});
  }
  cases.push_back({"unknown field",
                   cube,
                   {.color_field = "stress"},
                   "colour field 'stress' is not on the surface (it has: strain)"});
  {
    mesh::BoundarySurface s = cube;
    s.fields[0].values[6] = std::numeric_limits<double>::infinity();
    cases.push_back({"field inf",
                     s,
                     {.color_field = "strain"},
                     "colour field 'strain' is not finite at vertex 6"});
  }
  {
    // Animations (morph targets): a time per frame, increasing; frames of
    // the surface's vertices.
    GlbOptions o;
    o.morph_frames = {cube.positions};
    o.morph_times = {0.0};
    cases.push_back({"times", cube, o, "animation: 1 times for 2 frames"});
    o.morph_times = {0.5, 0.5};
    cases.push_back(
        {"order", cube, o, "animation: frame 1's time 0.5 is not finite and after the one before"});
    o.morph_frames = {Points::Zero(7, 3)};
    o.morph_times = {0.0, 1.0};
    cases.push_back({"frame size", cube, o, "animation: frame 1 has 7 vertices, the surface 8"});
  }
  ScopedTempDir tmp;
  for (const Case& c : cases) {
    const std::string path = tmp.path() + "/" + c.what + ".glb";
    EXPECT_THAT(WriteGlb(path, c.surface, c.options),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(path + ": " + c.message)))
        << c.what;
    EXPECT_FALSE(std::filesystem::exists(path)) << c.what << ": no file on error";
    std::string bytes = "kept";
    EXPECT_THAT(GlbBytes(c.surface, c.options, &bytes),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(c.message)))
        << c.what;
    EXPECT_EQ(bytes, "kept") << c.what << ": nothing appended on error";
  }
  EXPECT_THAT(WriteGlb("/nonexistent/dir/a.glb", cube),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("cannot open for writing")));
}

}  // namespace
}  // namespace dynsolid::io
