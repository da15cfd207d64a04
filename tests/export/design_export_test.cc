// Export of a design (solver/export/design_export.h): the current shape at
// any level, in each format, read back here (counts, the enclosed volume of
// the STL, the glb's layout) and by independent readers (meshio for PLY and
// VTU; the Khronos glTF validator for the glb). At the simulated level the
// export's vertices are the solid's own surface; bad requests are refused
// naming the field.
#include "solver/export/design_export.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/io/io_test_util.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::exporter {
namespace {

using ::testing::HasSubstr;

constexpr char kScene[] = R"pb(
  name: "block"
  mesh { block { nx: 2 ny: 1 nz: 1 } }
  subdivision { levels: 1 }
  materials { base { young_modulus: 1e5 density: 1000 damping: 100 } }
  constraints { fixed { box { min { x: -1 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } } } }
  loads { gravity { z: -9.81 } }
  solver { model: COROTATIONAL corotation: CONTROL_CELL time_step: 1e-3 }
)pb";

struct Fixture {
  std::unique_ptr<solid::Solid> solid;
  Points rest;
};

Fixture Bent() {
  Fixture f;
  auto scene = scene::ParseScene(kScene, "test");
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, "", std::nullopt);
  EXPECT_OK(d);
  auto s = solid::Solid::Create(*scene, *std::move(d), 1);
  EXPECT_OK(s);
  f.solid = *std::move(s);
  f.rest = f.solid->control_positions();
  for (int i = 0; i < 300; ++i) EXPECT_OK(f.solid->Step());
  return f;
}

DesignInput InputOf(const Fixture& f) {
  return DesignInput{&f.solid->discretization(), f.solid->control_positions(), f.rest};
}

uint32_t U32(const std::string& b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

float F32(const std::string& b, size_t at) {
  float v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// The volume an STL's triangles enclose (divergence theorem).
double StlVolume(const std::string& b) {
  const uint32_t n = U32(b, 80);
  double volume = 0;
  for (uint32_t t = 0; t < n; ++t) {
    const size_t at = 84 + 50 * static_cast<size_t>(t) + 12;
    Eigen::Vector3d v[3];
    for (int k = 0; k < 3; ++k) {
      v[k] = Eigen::Vector3d(F32(b, at + 12 * k), F32(b, at + 12 * k + 4), F32(b, at + 12 * k + 8));
    }
    volume += v[0].dot(v[1].cross(v[2])) / 6.0;
  }
  return volume;
}

TEST(DesignExportTest, EveryLevelOfTheSurfaceEnclosesTheSolidsVolumeAndTheSimulatedOneIsItsSurface) {
  const Fixture f = Bent();
  const DesignInput in = InputOf(f);
  std::vector<double> volumes;
  for (int level = 0; level <= 3; ++level) {
    SCOPED_TRACE(absl::StrCat("level ", level));
    ASSERT_OK_AND_ASSIGN(Exported stl, ExportDesign(in, {Format::kStl, level, ""}));
    ASSERT_GE(stl.bytes.size(), 84u);
    const uint32_t triangles = U32(stl.bytes, 80);
    EXPECT_EQ(stl.bytes.size(), 84u + 50u * triangles);
    // Every boundary face at this level is a quad: two triangles.
    EXPECT_EQ(triangles, 2 * stl.surface_faces);
    const double volume = StlVolume(stl.bytes);
    std::printf("level %d: %lld cells, %lld faces, enclosed volume %.6f m^3\n", level,
                static_cast<long long>(stl.cells), static_cast<long long>(stl.surface_faces), volume);
    EXPECT_GT(volume, 0) << "the faces point outward";
    volumes.push_back(volume);
  }
  // At the simulated level the surface encloses the solid (its rest volume,
  // barely changed by its sag); finer levels shrink towards the limit
  // shape, converging (each change at most half the one before).
  EXPECT_NEAR(volumes[1], f.solid->rest_volume(), 0.01 * f.solid->rest_volume());
  EXPECT_LT(volumes[2], volumes[1]);
  EXPECT_LT(volumes[3], volumes[2]);
  EXPECT_LT(volumes[2] - volumes[3], 0.5 * (volumes[1] - volumes[2]));
  // At the simulated level (1), the exported vertices are the surface
  // watchers see, bit for bit (OBJ writes the shortest text that reads
  // back to the same double).
  ASSERT_OK_AND_ASSIGN(Exported obj, ExportDesign(in, {Format::kObj, 1, ""}));
  std::set<std::array<double, 3>> exported;
  std::istringstream lines(obj.bytes);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("v ", 0) != 0) continue;
    std::array<double, 3> v;
    std::istringstream(line.substr(2)) >> v[0] >> v[1] >> v[2];
    exported.insert(v);
  }
  const Points watched = f.solid->SurfacePositions();
  EXPECT_EQ(static_cast<int64_t>(exported.size()), watched.rows());
  for (Eigen::Index i = 0; i < watched.rows(); ++i) {
    EXPECT_TRUE(exported.count({watched(i, 0), watched(i, 1), watched(i, 2)}))
        << "surface vertex " << i << " (" << watched.row(i) << ") is not in the export";
  }
}

TEST(DesignExportTest, PlyAndVtuOpenInMeshioWithTheDisplacementField) {
  const Fixture f = Bent();
  const DesignInput in = InputOf(f);
  io::testing::ScopedTempDir dir;
  ASSERT_OK_AND_ASSIGN(Exported ply, ExportDesign(in, {Format::kPly, 2, ""}));
  const std::string ply_path = dir.path() + "/design.ply";
  io::testing::WriteTextFile(ply_path, ply.bytes);
  io::testing::CommandResult r =
      io::testing::RunMeshio(ply_path, "--point-data displacement_x,displacement_magnitude");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  ASSERT_OK_AND_ASSIGN(Exported vtu, ExportDesign(in, {Format::kVtu, 2, ""}));
  const std::string vtu_path = dir.path() + "/design.vtu";
  io::testing::WriteTextFile(vtu_path, vtu.bytes);
  r = io::testing::RunMeshio(vtu_path, absl::StrCat("--point-data displacement,displacement_magnitude"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr(absl::StrCat("\"hexahedron\": ", vtu.cells)));
}

TEST(DesignExportTest, TheGlbIsValidWithColours) {
  const Fixture f = Bent();
  ASSERT_OK_AND_ASSIGN(Exported glb, ExportDesign(InputOf(f), {Format::kGlb, 2, "displacement"}));
  ASSERT_GE(glb.bytes.size(), 20u);
  EXPECT_EQ(std::memcmp(glb.bytes.data(), "glTF", 4), 0);
  EXPECT_EQ(U32(glb.bytes, 8), glb.bytes.size());
  EXPECT_NE(glb.bytes.find("COLOR_0"), std::string::npos);
  const std::string validator = io::testing::SourceDir() + "/tests/io/gltf";
  ASSERT_TRUE(std::filesystem::exists(validator + "/node_modules"))
      << "run npm ci in " << validator << " (scripts/setup_web.sh does)";
  io::testing::ScopedTempDir dir;
  const std::string path = dir.path() + "/design.glb";
  io::testing::WriteTextFile(path, glb.bytes);
  const io::testing::CommandResult r =
      io::testing::RunCommand("node '" + validator + "/validate.mjs' '" + path + "'");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(DesignExportTest, BadRequestsAreRefusedNamingTheField) {
  const Fixture f = Bent();
  DesignInput in = InputOf(f);
  EXPECT_THAT(ExportDesign(in, {Format::kObj, 7, ""}).status().message(),
              HasSubstr("level: 7 is not in [0, 6]"));
  ExportOptions big{Format::kObj, 6, ""};
  big.max_cells = 100000;
  EXPECT_THAT(ExportDesign(in, big).status().message(),
              HasSubstr("more than the export limit of 100000"));
  EXPECT_THAT(ExportDesign(in, {Format::kGlb, 1, "strain"}).status().message(),
              HasSubstr("color_field: \"strain\" is not a field of an export"));
  in.positions(3, 1) = NAN;
  EXPECT_THAT(ExportDesign(in, {Format::kObj, 1, ""}).status().message(),
              HasSubstr("positions: control point 3 is not finite"));
  in.positions = in.positions.topRows(2);
  EXPECT_THAT(ExportDesign(in, {Format::kObj, 1, ""}).status().message(),
              HasSubstr("positions: 2 x 3 values for"));
}

}  // namespace
}  // namespace dynsolid::exporter
