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
#include <map>
#include <algorithm>
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
#include "solver/subdivision/mcj.h"
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

// The volume the cells of `fine` enclose at positions x: each cell's faces
// fan-triangulated from their first vertex (as the export triangulates), in
// the cell's outward orientation, summed by the divergence theorem. A face
// two cells share cancels exactly (a reversed loop has the same diagonal),
// so this is the boundary's volume computed from the cells, not from it.
double CellsVolume(const mesh::CellComplex& fine, const Points& x) {
  double volume = 0;
  for (int32_t c = 0; c < fine.num_cells(); ++c) {
    const auto faces = fine.cell_faces(c);
    const auto flipped = fine.cell_face_flipped(c);
    for (size_t k = 0; k < faces.size(); ++k) {
      std::vector<int32_t> loop(fine.face_vertices(faces[k]).begin(),
                                fine.face_vertices(faces[k]).end());
      if (flipped[k]) std::reverse(loop.begin() + 1, loop.end());
      const Eigen::Vector3d a = x.row(loop[0]).transpose();
      for (size_t i = 1; i + 1 < loop.size(); ++i) {
        volume += a.dot(Eigen::Vector3d(x.row(loop[i]).transpose())
                            .cross(Eigen::Vector3d(x.row(loop[i + 1]).transpose()))) / 6.0;
      }
    }
  }
  return volume;
}

// A slicer's checks on the STL: closed and oriented (every edge, by its
// end points, in exactly two triangles, once each way round), and its
// enclosed volume that of the level's cells at the same positions (within
// the float32 rounding of STL coordinates: 1e-6 relative). The volume
// equals the solid's FEM rest volume at rest only where every element is
// trilinear and every boundary quad planar; measured, printed.
TEST(DesignExportTest, TheStlIsClosedAndOrientedAndEnclosesTheCellsVolume) {
  const Fixture f = Bent();
  for (const bool at_rest : {false, true}) {
    DesignInput in = InputOf(f);
    if (at_rest) in.positions = f.rest;
    for (int level = 0; level <= 3; ++level) {
      SCOPED_TRACE(absl::StrCat(at_rest ? "at rest" : "bent", ", level ", level));
      ASSERT_OK_AND_ASSIGN(Exported stl, ExportDesign(in, {Format::kStl, level, ""}));
      const uint32_t n = U32(stl.bytes, 80);
      using P = std::array<float, 3>;
      std::map<std::pair<P, P>, int> directed;
      for (uint32_t t = 0; t < n; ++t) {
        const size_t at = 84 + 50 * static_cast<size_t>(t) + 12;
        P v[3];
        for (int k = 0; k < 3; ++k) {
          for (int c = 0; c < 3; ++c) v[k][c] = F32(stl.bytes, at + 12 * k + 4 * c);
        }
        for (int k = 0; k < 3; ++k) ++directed[{v[k], v[(k + 1) % 3]}];
      }
      int open = 0, twice = 0;
      for (const auto& [edge, count] : directed) {
        if (count != 1) ++twice;
        if (directed.count({edge.second, edge.first}) != 1) ++open;
      }
      EXPECT_EQ(open, 0) << "edges with no triangle the other way round (holes)";
      EXPECT_EQ(twice, 0) << "edges run the same way by two triangles (inconsistent winding)";
      const double volume = StlVolume(stl.bytes);
      ASSERT_OK_AND_ASSIGN(subdivision::Hierarchy h,
                           subdivision::Subdivide(f.solid->discretization().hierarchy.control, level,
                                                  f.solid->discretization().control_sharp,
                                                  [](const mesh::CellComplex&) {}));
      const double cells = CellsVolume(*h.fine, h.a * in.positions);
      EXPECT_GT(volume, 0);
      EXPECT_NEAR(volume, cells, 1e-6 * cells);
      if (at_rest && level == f.solid->discretization().hierarchy.levels) {
        std::printf("at rest, the simulated level: the STL encloses %.12f m^3, the cells %.12f, "
                    "the solid's FEM rest volume %.12f (relative difference %.2e)\n",
                    volume, cells, f.solid->rest_volume(),
                    std::abs(cells - f.solid->rest_volume()) / f.solid->rest_volume());
      }
    }
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
  // The cell data: strain from the nodes, the materials from the design.
  // The block is one material (E 1e5 Pa, 1000 kg/m^3) without clay: the
  // sums are known at the solid's level (each element's mean) and at a
  // finer one (the control cells'); at rest no cell is strained.
  ASSERT_OK_AND_ASSIGN(MaterialFields materials,
                       MaterialFieldsOf(f.solid->discretization(), f.solid->SaveDesign()));
  DesignInput with = in;
  with.materials = &materials;
  for (const int level : {1, 2}) {
    ASSERT_OK_AND_ASSIGN(Exported v, ExportDesign(with, {Format::kVtu, level, ""}));
    io::testing::WriteTextFile(vtu_path, v.bytes);
    r = io::testing::RunMeshio(
        vtu_path, absl::StrCat("--cell-data strain,young_modulus,density,plastic_strain "
                               "--cell-data-sum young_modulus=", 1e5 * v.cells,
                               ",density=", 1000.0 * v.cells, ",plastic_strain=0"));
    EXPECT_EQ(r.exit_code, 0) << "level " << level << ": " << r.output;
  }
  with.positions = f.rest;
  ASSERT_OK_AND_ASSIGN(Exported at_rest, ExportDesign(with, {Format::kVtu, 1, ""}));
  io::testing::WriteTextFile(vtu_path, at_rest.bytes);
  r = io::testing::RunMeshio(vtu_path, "--cell-data-sum strain=0");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // Bent (the block sags under its weight): the cells strain.
  with.positions = f.solid->control_positions();
  ASSERT_OK_AND_ASSIGN(Exported bent, ExportDesign(with, {Format::kVtu, 1, ""}));
  io::testing::WriteTextFile(vtu_path, bent.bytes);
  r = io::testing::RunMeshio(vtu_path, "--cell-data strain");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const size_t at = r.output.find("\"strain\": [[");
  ASSERT_NE(at, std::string::npos) << r.output;
  const size_t comma = r.output.find("], ", at);
  const double sum = std::stod(r.output.substr(comma + 3));
  std::printf("bent block: the cells' strain sums to %g over %lld cells\n", sum,
              static_cast<long long>(bent.cells));
  EXPECT_GT(sum, 1e-6 * bent.cells);
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
