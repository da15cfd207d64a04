// Tests of the Gmsh and VTK legacy readers: good files give the right
// cells with outward loops; every bad file gives its own message.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <ostream>
#include <string>
#include <vector>

#include "solver/io/mesh_readers.h"
#include "tests/io/io_test_util.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::io {
namespace {

using ::dynsolid::testing::StatusIs;
using testing::Canonical;
using testing::CellVolume;
using testing::DataPath;
using ::testing::HasSubstr;
using testing::ScopedTempDir;
using testing::SourceDir;
using ::testing::StartsWith;
using testing::WriteTextFile;

// The mixed mesh of scenes/meshes/mixed.*: hexahedron, pyramid, prism,
// tetrahedron, with these volumes (unit hexahedron, pyramid of height 0.6,
// prism of cross-section 0.4 and length 1, tetrahedron of base 0.4 and
// height 0.6).
constexpr double kHexVolume = 1.0;
constexpr double kPyramidVolume = 0.2;
constexpr double kPrismVolume = 0.4;
constexpr double kTetVolume = 0.08;
constexpr double kTolerance = 1e-12;

// Checks counts, that every loop of every cell is outward (positive signed
// volume) and that the total volume is that of the mixed mesh.
void ExpectMixedMesh(const mesh::MeshInput& in, size_t num_cells) {
  EXPECT_EQ(in.vertices.rows(), 12) << "vertices of the mixed mesh";
  ASSERT_EQ(in.cells.size(), num_cells) << "cells of the mixed mesh";
  double total = 0.0;
  for (size_t c = 0; c < in.cells.size(); ++c) {
    const double v = CellVolume(in, c);
    EXPECT_GT(v, 0.0) << "signed volume of cell " << c << " (loops must be outward)";
    total += v;
  }
  EXPECT_NEAR(total, kHexVolume + kPyramidVolume + kPrismVolume + kTetVolume, kTolerance)
      << "total volume of the mixed mesh";
}

// Cell volumes in file order for the four-cell files.
void ExpectFourCellVolumes(const mesh::MeshInput& in) {
  ASSERT_EQ(in.cells.size(), 4u);
  EXPECT_EQ(in.cells[0].size(), 6u) << "faces of the hexahedron";
  EXPECT_EQ(in.cells[1].size(), 5u) << "faces of the pyramid";
  EXPECT_EQ(in.cells[2].size(), 5u) << "faces of the prism";
  EXPECT_EQ(in.cells[3].size(), 4u) << "faces of the tetrahedron";
  EXPECT_NEAR(CellVolume(in, 0), kHexVolume, kTolerance) << "hexahedron volume";
  EXPECT_NEAR(CellVolume(in, 1), kPyramidVolume, kTolerance) << "pyramid volume";
  EXPECT_NEAR(CellVolume(in, 2), kPrismVolume, kTolerance) << "prism volume";
  EXPECT_NEAR(CellVolume(in, 3), kTetVolume, kTolerance) << "tetrahedron volume";
}

std::string ScenePath(const std::string& name) { return SourceDir() + "/scenes/meshes/" + name; }

TEST(GmshReaderTest, ReadsMixedMesh41) {
  const std::string path = ScenePath("mixed.msh");
  absl::StatusOr<mesh::MeshInput> in = ReadGmsh(path);
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 4);
  ExpectFourCellVolumes(*in);
  EXPECT_EQ(in->origin, path);
}

TEST(GmshReaderTest, ReadsVersion22WithTagsAndSkipsLowerDimensionalElements) {
  absl::StatusOr<mesh::MeshInput> in = ReadGmsh(DataPath("mixed_v22.msh"));
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 4);
  ExpectFourCellVolumes(*in);
}

TEST(GmshReaderTest, ReadsVersion41WithSparseTagsBlocksAndParametricNodes) {
  absl::StatusOr<mesh::MeshInput> in = ReadGmsh(DataPath("mixed_v41.msh"));
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 4);
  ExpectFourCellVolumes(*in);
  // Vertices are numbered in order of appearance: tag 5000000 (the origin)
  // first, then tag 7 (the pyramid's apex).
  EXPECT_EQ(in->vertices.row(0), Eigen::RowVector3d(0, 0, 0)) << "vertex 0";
  EXPECT_EQ(in->vertices.row(1), Eigen::RowVector3d(0.5, 0.5, 1.6)) << "vertex 1";
}

TEST(VtkLegacyReaderTest, ReadsClassicLayout) {
  const std::string path = ScenePath("mixed.vtk");
  absl::StatusOr<mesh::MeshInput> in = ReadVtkLegacy(path);
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 4);
  ExpectFourCellVolumes(*in);
  EXPECT_EQ(in->origin, path);
}

TEST(VtkLegacyReaderTest, Reads51LayoutWithVoxelAndSkipsTriangle) {
  absl::StatusOr<mesh::MeshInput> in = ReadVtkLegacy(DataPath("mixed_v51.vtk"));
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 4);
  ExpectFourCellVolumes(*in);
}

TEST(VtkLegacyReaderTest, ReadsPolyhedron) {
  absl::StatusOr<mesh::MeshInput> in = ReadVtkLegacy(DataPath("mixed_polyhedron.vtk"));
  ASSERT_OK(in);
  ExpectMixedMesh(*in, 3);
  EXPECT_EQ(in->cells[0].size(), 9u) << "faces of the hexahedron + pyramid polyhedron";
  EXPECT_NEAR(CellVolume(*in, 0), kHexVolume + kPyramidVolume, kTolerance) << "polyhedron volume";
}

TEST(VtkLegacyReaderTest, ReversesInwardPolyhedron) {
  // A unit cube as a polyhedron whose faces all point inward.
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/inward.vtk";
  WriteTextFile(path,
                "# vtk DataFile Version 4.2\ninward cube\nASCII\nDATASET UNSTRUCTURED_GRID\n"
                "POINTS 8 float\n0 0 0 1 0 0 1 1 0 0 1 0 0 0 1 1 0 1 1 1 1 0 1 1\n"
                "CELLS 1 32\n31 6 4 0 1 2 3 4 4 7 6 5 4 0 4 5 1 4 1 5 6 2 4 2 6 7 3 4 3 7 4 0\n"
                "CELL_TYPES 1\n42\n");
  absl::StatusOr<mesh::MeshInput> in = ReadVtkLegacy(path);
  ASSERT_OK(in);
  ASSERT_EQ(in->cells.size(), 1u);
  EXPECT_NEAR(CellVolume(*in, 0), 1.0, kTolerance) << "volume after reorientation";
}

TEST(MeshReadersTest, AllMixedFilesDescribeTheSameCells) {
  absl::StatusOr<mesh::MeshInput> vtk = ReadMeshFile(ScenePath("mixed.vtk"));
  absl::StatusOr<mesh::MeshInput> msh = ReadMeshFile(ScenePath("mixed.msh"));
  ASSERT_OK(vtk);
  ASSERT_OK(msh);
  EXPECT_EQ(vtk->vertices, msh->vertices) << "mixed.vtk and mixed.msh list the same vertices";
  EXPECT_EQ(vtk->cells, msh->cells) << "mixed.vtk and mixed.msh give the same loops";
  const auto reference = Canonical(*vtk);
  for (const char* name : {"mixed_v22.msh", "mixed_v41.msh", "mixed_v51.vtk"}) {
    absl::StatusOr<mesh::MeshInput> other = ReadMeshFile(DataPath(name));
    ASSERT_OK(other);
    EXPECT_TRUE(Canonical(*other) == reference) << name << " differs from mixed.vtk";
  }
}

// An independent writer's files (meshio's VTK 4.2 and 5.1 layouts and Gmsh
// 2.2) give the same cells: checks the node orderings (notably VTK's wedge
// against Gmsh's prism) against another implementation. (meshio's own
// Gmsh 4.1 writer fails on multi-block meshes; io_gmsh_test reads real
// Gmsh 4.1 output instead.)
TEST(MeshReadersTest, ReadsFilesWrittenByMeshio) {
  ScopedTempDir tmp;
  const std::string script = tmp.path() + "/convert.py";
  WriteTextFile(script,
                "import sys, meshio\n"
                "r = meshio.read(sys.argv[1])\n"
                "m = meshio.Mesh(r.points, r.cells)\n"
                "d = sys.argv[2]\n"
                "meshio.write(d + '/vtk42.vtk', m, file_format='vtk42', binary=False)\n"
                "meshio.write(d + '/vtk51.vtk', m, file_format='vtk51', binary=False)\n"
                "meshio.write(d + '/gmsh22.msh', m, file_format='gmsh22', binary=False)\n");
  const testing::CommandResult r = testing::RunCommand(
      "/usr/bin/python3 '" + script + "' '" + ScenePath("mixed.msh") + "' '" + tmp.path() + "'");
  ASSERT_EQ(r.exit_code, 0) << "meshio conversion (run scripts/setup.sh for python3-meshio):\n"
                            << r.output;
  absl::StatusOr<mesh::MeshInput> reference = ReadMeshFile(ScenePath("mixed.vtk"));
  ASSERT_OK(reference);
  for (const char* name : {"vtk42.vtk", "vtk51.vtk", "gmsh22.msh"}) {
    absl::StatusOr<mesh::MeshInput> in = ReadMeshFile(tmp.path() + "/" + name);
    ASSERT_OK(in) << name;
    ExpectMixedMesh(*in, 4);
    EXPECT_TRUE(Canonical(*in) == Canonical(*reference)) << name << " differs from mixed.vtk";
  }
}

TEST(MeshReadersTest, DispatchesOnExtension) {
  ScopedTempDir tmp;
  const std::string dir = tmp.path();
  WriteTextFile(dir + "/UPPER.VTK", testing::ReadTextFile(ScenePath("mixed.vtk")));
  EXPECT_OK(ReadMeshFile(dir + "/UPPER.VTK"));
  EXPECT_THAT(ReadMeshFile(dir + "/mesh.obj"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("unknown mesh file extension '.obj'")));
}

TEST(MeshReadersTest, MissingFileIsNotFound) {
  EXPECT_THAT(ReadGmsh("/nonexistent/dir/mesh.msh"),
              StatusIs(absl::StatusCode::kNotFound,
                       StartsWith("/nonexistent/dir/mesh.msh: file not found")));
  EXPECT_THAT(ReadVtkLegacy("/nonexistent/mesh.vtk"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("file not found")));
  EXPECT_THAT(ReadMeshFile("/nonexistent/mesh.msh"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("file not found")));
}

// A bad file: its name (extension picks the reader), contents, and the
// expected message after "path:".
struct BadFile {
  std::string name;
  std::string contents;
  std::string message;  // expected to follow "<path>:"
};

void PrintTo(const BadFile& b, std::ostream* os) { *os << b.name; }

class BadFileTest : public ::testing::TestWithParam<BadFile> {};

TEST_P(BadFileTest, FailsWithItsMessage) {
  const BadFile& bad = GetParam();
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/" + bad.name;
  WriteTextFile(path, bad.contents);
  absl::StatusOr<mesh::MeshInput> in = ReadMeshFile(path);
  EXPECT_THAT(in,
              StatusIs(absl::StatusCode::kInvalidArgument, StartsWith(path + ":" + bad.message)));
}

constexpr char kGmsh22Head[] =
    "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"                      // lines 1-3
    "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"  // lines 4-10
    "$Elements\n";                                                // line 11

constexpr char kGmsh41Head[] = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";  // lines 1-3

constexpr char kVtkHead[] =
    "# vtk DataFile Version 4.2\ntitle\nASCII\nDATASET UNSTRUCTURED_GRID\n";  // lines 1-4

constexpr char kVtkTetPoints[] = "POINTS 4 double\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";  // lines 5-9

std::string Gmsh22(const std::string& elements) { return std::string(kGmsh22Head) + elements; }

INSTANTIATE_TEST_SUITE_P(
    Gmsh, BadFileTest,
    ::testing::Values(
        BadFile{"empty.msh", "", "1: empty file"},
        BadFile{"blank.msh", "  \n\n \t\n", "1: empty file"},
        BadFile{"no_format.msh", "$Nodes\n", "1: expected $MeshFormat"},
        BadFile{"binary.msh", "$MeshFormat\n4.1 1 8\n\x01\x00\x00\x00\n", "2: binary Gmsh file"},
        BadFile{"binary22.msh", "$MeshFormat\n2.2 1 8\n", "2: binary Gmsh file"},
        BadFile{"version.msh", "$MeshFormat\n4 0 8\n$EndMeshFormat\n",
                "2: unsupported Gmsh format version '4'"},
        BadFile{"truncated.msh",
                Gmsh22("12\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 4\n3 4 2 0 1 1 2 3 4\n"
                       "4 4 2 0 1 1 2 3 4\n5 4 2 0 1 1 2 3 4\n6 4 2 0 1 1 2 3 4\n"
                       "7 4 2 0 1 1 2 3 4\n"),
                "19: unexpected end of file in $Elements: expected 12 elements, got 7"},
        BadFile{"ended_early.msh", Gmsh22("2\n1 4 2 0 1 1 2 3 4\n$EndElements\n"),
                "14: $Elements ended early at '$EndElements': expected 2 elements, got 1"},
        BadFile{"too_many.msh", Gmsh22("1\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 4\n$EndElements\n"),
                "14: expected $EndElements after 1 elements (as declared), found"},
        BadFile{"bad_coordinate.msh",
                "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n2 1 0.5x 0\n",
                "7: bad number '0.5x' for the y coordinate of node 2: expected a number"},
        BadFile{"bad_node_tag.msh", Gmsh22("1\n1 4 2 0 1 1 2 three 4\n$EndElements\n"),
                "13: bad number 'three' for node 3 of element 1: expected an integer"},
        BadFile{"bad_count.msh", Gmsh22("many\n"),
                "12: bad number 'many' for the number of elements"},
        BadFile{"huge_count.msh", Gmsh22("99999999999\n"),
                "12: the number of elements 99999999999 is too large"},
        BadFile{"nan.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n2 nan 0 0\n",
                "7: coordinate 'nan' (x) of node 2 is not finite"},
        BadFile{"inf.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 -inf\n",
                "6: coordinate '-inf' (z) of node 1 is not finite"},
        BadFile{"second_order.msh", Gmsh22("1\n1 11 2 0 1 1 2 3 4 1 2 3 4 1 2\n$EndElements\n"),
                "13: unsupported Gmsh element type 11 (10-node second-order tetrahedron)"},
        BadFile{"unknown_type.msh", Gmsh22("1\n1 92 2 0 1 1 2 3 4\n$EndElements\n"),
                "13: unsupported Gmsh element type 92: only linear volume elements"},
        BadFile{"undefined_node.msh", Gmsh22("1\n1 4 2 0 1 1 2 3 99\n$EndElements\n"),
                "13: element 1: node tag 99 is not defined in $Nodes"},
        BadFile{"duplicate_node.msh",
                "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n3 0 0 0\n3 1 0 0\n$EndNodes\n",
                "7: node tag 3 is defined twice (first at line 6)"},
        BadFile{"short_element.msh", Gmsh22("1\n1 5 2 0 1 1 2 3 4\n$EndElements\n"),
                "13: element 1 (8-node hexahedron) with 2 tags has 9 fields: expected 13"},
        BadFile{"no_volume.msh", Gmsh22("1\n1 2 2 0 1 1 2 3\n$EndElements\n"),
                "14: no volume elements"},
        BadFile{"no_elements.msh",
                "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n",
                "7: no $Elements section"},
        BadFile{"open_section.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Comments\nhello\n",
                "5: unexpected end of file in $Comments (opened at line 4): expected $EndComments"},
        BadFile{"truncated41.msh",
                std::string(kGmsh41Head) + "$Nodes\n1 12 1 12\n3 1 0 12\n1\n2\n3\n4\n5\n",
                "11: unexpected end of file in $Nodes: expected 12 nodes, got 0"},
        BadFile{"type41.msh",
                std::string(kGmsh41Head) +
                    "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                    "$EndNodes\n$Elements\n1 1 1 1\n3 1 17 1\n",
                "18: unsupported Gmsh element type 17 (20-node second-order hexahedron)"},
        BadFile{"count41.msh",
                std::string(kGmsh41Head) +
                    "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                    "$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3\n",
                "19: element 1 (4-node tetrahedron) has 3 node tags: expected 4"}),
    [](const ::testing::TestParamInfo<BadFile>& info) {
      std::string name = info.param.name;
      for (char& c : name) {
        if (c == '.') c = '_';
      }
      return name;
    });

INSTANTIATE_TEST_SUITE_P(
    Vtk, BadFileTest,
    ::testing::Values(
        BadFile{"empty.vtk", "", "1: empty file"},
        BadFile{"no_header.vtk", "POINTS 1 float\n0 0 0\n",
                "1: expected '# vtk DataFile Version x.x'"},
        BadFile{"binary.vtk",
                "# vtk DataFile Version 4.2\ntitle\nBINARY\nDATASET UNSTRUCTURED_GRID\n",
                "3: binary VTK file"},
        BadFile{"format.vtk", "# vtk DataFile Version 4.2\ntitle\n", "3: expected ASCII or BINARY"},
        BadFile{"polydata.vtk", "# vtk DataFile Version 4.2\ntitle\nASCII\nDATASET POLYDATA\n",
                "4: unsupported DATASET 'POLYDATA': expected UNSTRUCTURED_GRID"},
        BadFile{"truncated_points.vtk", std::string(kVtkHead) + "POINTS 12 float\n0 0 0 1 0 0\n",
                "6: unexpected end of file in POINTS: expected 12 points, got 2"},
        BadFile{"bad_point.vtk", std::string(kVtkHead) + "POINTS 2 float\n0 0 0\n1 O 0\n",
                "7: bad number 'O' for the y coordinate of point 1: expected a number"},
        BadFile{"nan.vtk", std::string(kVtkHead) + "POINTS 2 float\n0 0 0\n1 0 NaN\n",
                "7: coordinate 'NaN' (z) of point 1 is not finite"},
        BadFile{"int_points.vtk", std::string(kVtkHead) + "POINTS 2 int\n",
                "5: unsupported POINTS data type 'int': expected float or double"},
        BadFile{"truncated_cells.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 4 20\n4 0 1 2 3\n4 0 1 2 3\n",
                "12: unexpected end of file in CELLS: expected 4 cells, got 2"},
        BadFile{"bad_cell.vtk", std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 x 3\n",
                "11: bad number 'x' in cell 0 of CELLS: expected an integer"},
        BadFile{"cells_size.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 6\n4 0 1 2 3\nCELL_TYPES 1\n10\n",
                "11: CELLS declares size 6 but its 1 cells hold 5 values"},
        BadFile{"point_id.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 4\nCELL_TYPES 1\n10\n",
                "11: cell 0 refers to point 4: expected 0 to 3 (POINTS has 4)"},
        BadFile{"type.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n25\n",
                "13: unsupported VTK cell type 25 (quadratic hexahedron) for cell 0"},
        BadFile{"count.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n12\n",
                "11: cell 0 is a VTK_HEXAHEDRON (type 12) and needs 8 points, but lists 4"},
        BadFile{
            "types_count.vtk",
            std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 2\n10 10\n",
            "12: CELL_TYPES has 2 entries: expected one per cell, 1"},
        BadFile{"truncated_types.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 3\n10\n",
                "13: unexpected end of file in CELL_TYPES: expected 3 cell types, got 1"},
        BadFile{"no_types.vtk", std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 5\n4 0 1 2 3\n",
                "11: no CELL_TYPES section"},
        BadFile{"offsets.vtk",
                std::string(kVtkHead) + kVtkTetPoints +
                    "CELLS 2 5\nOFFSETS vtktypeint64\n0 4\nCONNECTIVITY vtktypeint64\n0 1 2 3\n",
                "11: the last OFFSETS value is 4: expected the CONNECTIVITY size 5"},
        BadFile{"polyhedron.vtk",
                std::string(kVtkHead) + kVtkTetPoints +
                    "CELLS 1 14\n13 4 3 0 2 1 3 0 1 3 3 1 2 3\nCELL_TYPES 1\n42\n",
                "11: polyhedron cell 0: the stream ends after 3 of 4 faces"},
        BadFile{"keyword.vtk", std::string(kVtkHead) + kVtkTetPoints + "CELLZ 1 5\n",
                "10: unexpected keyword 'CELLZ'"},
        BadFile{"lines_only.vtk",
                std::string(kVtkHead) + kVtkTetPoints + "CELLS 1 3\n2 0 1\nCELL_TYPES 1\n3\n",
                "12: no volume cells"}),
    [](const ::testing::TestParamInfo<BadFile>& info) {
      std::string name = info.param.name;
      for (char& c : name) {
        if (c == '.') c = '_';
      }
      return name;
    });

}  // namespace
}  // namespace dynsolid::io
