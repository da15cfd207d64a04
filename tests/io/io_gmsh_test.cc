// End-to-end: real Gmsh (Debian's /usr/bin/gmsh) meshes boxes with
// hexahedra, tetrahedra and prisms, in formats 2.2 and 4.1; ReadGmsh reads
// them; the control complex builds and subdivides one MacCracken-Joy level.
// meshio reads the same files as an independent count.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "solver/io/mesh_readers.h"
#include "solver/mesh/cell_complex.h"
#include "solver/subdivision/mcj.h"
#include "tests/io/io_test_util.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::io {
namespace {

using testing::CellVolume;
using testing::RunCommand;
using testing::ScopedTempDir;
using testing::WriteTextFile;

// Path of the gmsh executable, or "" when there is none.
std::string FindGmsh() {
  if (access("/usr/bin/gmsh", X_OK) == 0) return "/usr/bin/gmsh";
  const testing::CommandResult r = RunCommand("command -v gmsh");
  std::string path = r.output;
  while (!path.empty() && (path.back() == '\n' || path.back() == '\r')) path.pop_back();
  return r.exit_code == 0 ? path : std::string();
}

struct GmshCase {
  std::string name;
  std::string geo;          // a unit box [0,1]^3
  std::string format;       // msh22 or msh41
  std::string meshio_type;  // the volume cell type meshio reports
  int corners;              // vertices per cell (new cells per cell after one level)
  int expected_vertices;    // -1: not fixed by the geometry
  int expected_cells;
};

// 2x2x2 hexahedra: Transfinite curves, surfaces and volume, recombined.
constexpr char kHexGeo[] = R"(SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 1};
Transfinite Curve{:} = 3;
Transfinite Surface{:};
Recombine Surface{:};
Transfinite Volume{:};
)";

// Unstructured tetrahedra.
constexpr char kTetGeo[] = R"(SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 1};
Mesh.MeshSizeMin = 0.5;
Mesh.MeshSizeMax = 0.5;
)";

// Prisms: a triangulated square extruded in two layers (without Recombine
// Gmsh would split each prism into three tetrahedra).
constexpr char kPrismGeo[] = R"(SetFactory("OpenCASCADE");
Rectangle(1) = {0, 0, 0, 1, 1};
Mesh.MeshSizeMin = 0.5;
Mesh.MeshSizeMax = 0.5;
Extrude {0, 0, 1} { Surface{1}; Layers{2}; Recombine; }
)";

void PrintTo(const GmshCase& c, std::ostream* os) { *os << c.name; }

class GmshMeshTest : public ::testing::TestWithParam<GmshCase> {};

TEST_P(GmshMeshTest, ReadsBuildsAndSubdivides) {
  const GmshCase& c = GetParam();
  const std::string gmsh = FindGmsh();
  ASSERT_FALSE(gmsh.empty())
      << "gmsh not found (looked for /usr/bin/gmsh and on PATH): run scripts/setup.sh, which "
         "installs Debian's gmsh package";

  ScopedTempDir dir;
  const std::string geo = dir.path() + "/box.geo";
  const std::string msh = dir.path() + "/box.msh";
  WriteTextFile(geo, c.geo);
  const testing::CommandResult run = RunCommand(gmsh + " -3 -nopopup -v 2 -format " + c.format +
                                                " -o '" + msh + "' '" + geo + "'");
  ASSERT_EQ(run.exit_code, 0) << "gmsh failed on\n" << c.geo << "\n" << run.output;

  absl::StatusOr<mesh::MeshInput> input = ReadGmsh(msh);
  ASSERT_OK(input);
  const int64_t num_vertices = input->vertices.rows();
  const int64_t num_cells = static_cast<int64_t>(input->cells.size());
  if (c.expected_vertices >= 0) {
    EXPECT_EQ(num_vertices, c.expected_vertices) << "vertices";
  }
  if (c.expected_cells >= 0) {
    EXPECT_EQ(num_cells, c.expected_cells) << "cells";
  }
  ASSERT_GT(num_cells, 0);

  // Every cell outward, and together they fill the unit box.
  double total = 0.0;
  for (size_t i = 0; i < input->cells.size(); ++i) {
    const double v = CellVolume(*input, i);
    EXPECT_GT(v, 0.0) << "signed volume of cell " << i;
    total += v;
  }
  EXPECT_NEAR(total, 1.0, 1e-12) << "total volume of the unit box";

  // meshio counts the same points and volume cells in the same file.
  const testing::CommandResult meshio =
      testing::RunMeshio(msh, "--points " + std::to_string(num_vertices));
  EXPECT_EQ(meshio.exit_code, 0) << meshio.output;
  EXPECT_THAT(meshio.output,
              ::testing::HasSubstr("\"" + c.meshio_type + "\": " + std::to_string(num_cells)))
      << "meshio's count of " << c.meshio_type << " cells";

  absl::StatusOr<mesh::CellComplex> complex = mesh::CellComplex::FromInput(*input);
  ASSERT_OK(complex);
  EXPECT_EQ(complex->num_vertices(), num_vertices);
  EXPECT_EQ(complex->num_cells(), num_cells);
  const mesh::CellComplex::BoundaryCounts boundary = complex->CountBoundary();
  EXPECT_EQ(boundary.euler(), 2) << "Euler characteristic of the box's boundary";
  double complex_volume = 0.0;
  for (int32_t i = 0; i < complex->num_cells(); ++i) complex_volume += complex->CellVolume(i);
  EXPECT_NEAR(complex_volume, 1.0, 1e-12) << "volume of the control complex";

  auto control = std::make_shared<const mesh::CellComplex>(*std::move(complex));
  absl::StatusOr<subdivision::Hierarchy> hierarchy = subdivision::Subdivide(control, 1, {});
  ASSERT_OK(hierarchy);
  ASSERT_NE(hierarchy->fine, nullptr);
  EXPECT_EQ(hierarchy->levels, 1);
  // One new cell per (cell, corner) pair.
  EXPECT_EQ(hierarchy->fine->num_cells(), num_cells * c.corners) << "cells after one level";
  EXPECT_EQ(hierarchy->a.rows(), hierarchy->fine->num_vertices());
  EXPECT_EQ(hierarchy->a.cols(), num_vertices);
  for (int32_t i = 0; i < hierarchy->fine->num_cells(); ++i) {
    ASSERT_GT(hierarchy->fine->CellVolume(i), 0.0) << "volume of fine cell " << i;
  }
}

std::vector<GmshCase> Cases() {
  std::vector<GmshCase> cases;
  for (const char* format : {"msh22", "msh41"}) {
    const std::string f = format;
    // 3x3x3 nodes, 8 hexahedra.
    cases.push_back({"hexahedra_" + f, kHexGeo, f, "hexahedron", 8, 27, 8});
    cases.push_back({"tetrahedra_" + f, kTetGeo, f, "tetra", 4, -1, -1});
    cases.push_back({"prisms_" + f, kPrismGeo, f, "wedge", 6, -1, -1});
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Box, GmshMeshTest, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<GmshCase>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace dynsolid::io
