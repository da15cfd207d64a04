// Tests of the OBJ, PLY and VTU writers: counts and layout checked here,
// and every file read back by an independent reader (meshio, through
// tests/io/read_vtu.py and Debian's /usr/bin/python3).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "solver/io/surface_writers.h"
#include "solver/io/volume_mesh.h"
#include "tests/io/io_test_util.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::io {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using testing::ReadTextFile;
using testing::ExpectMeshioReads;
using testing::ScopedTempDir;

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// The surface of a square pyramid: one quad (the base, facing -z) and four
// triangles, all outward.
mesh::BoundarySurface PyramidSurface() {
  mesh::BoundarySurface s;
  s.positions.resize(5, 3);
  s.positions << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0.5, 0.5, 1;
  s.mesh_vertex = {0, 1, 2, 3, 4};
  for (const std::vector<int32_t>& loop : std::vector<std::vector<int32_t>>{
           {0, 3, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}}) {
    s.faces.items.insert(s.faces.items.end(), loop.begin(), loop.end());
    s.faces.offsets.push_back(static_cast<int32_t>(s.faces.items.size()));
  }
  s.mesh_face = {0, 1, 2, 3, 4};
  return s;
}

TEST(ObjWriterTest, WritesVerticesAndOneBasedFaces) {
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/pyramid.obj";
  ASSERT_OK(WriteObj(path, PyramidSurface()));
  int vertices = 0;
  std::vector<std::string> faces;
  for (const std::string& line : Lines(ReadTextFile(path))) {
    if (line.rfind("v ", 0) == 0) ++vertices;
    if (line.rfind("f ", 0) == 0) faces.push_back(line);
  }
  EXPECT_EQ(vertices, 5) << "'v' lines";
  EXPECT_THAT(faces, ElementsAre("f 1 4 3 2", "f 1 2 5", "f 2 3 5", "f 3 4 5", "f 4 1 5"));
  ExpectMeshioReads(path, "--points 5 --cells quad=1,triangle=4");
}

TEST(PlyWriterTest, WritesHeaderFieldsAndPolygons) {
  mesh::BoundarySurface s = PyramidSurface();
  s.fields.push_back({"stiffness", 1, {1, 2, 3, 4, 5}});
  s.fields.push_back({"displacement", 3, std::vector<double>(15, 0.25)});
  s.fields.push_back({"uv", 2, std::vector<double>(10, 1.0)});
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/pyramid.ply";
  ASSERT_OK(WritePly(path, s));
  const std::vector<std::string> lines = Lines(ReadTextFile(path));
  ASSERT_GE(lines.size(), 20u);
  const std::vector<std::string> header(lines.begin(), lines.begin() + 18);
  EXPECT_THAT(header, ElementsAre("ply", "format ascii 1.0", "comment dynsolid boundary surface",
                                  "element vertex 5", "property double x", "property double y",
                                  "property double z", "property float stiffness",
                                  "property float displacement_x", "property float displacement_y",
                                  "property float displacement_z", "property float uv_0",
                                  "property float uv_1", "element face 5",
                                  "property list uchar int vertex_indices", "end_header",
                                  "0 0 0 1 0.25 0.25 0.25 1 1", "1 0 0 2 0.25 0.25 0.25 1 1"));
  ASSERT_EQ(lines.size(), 16u + 5u + 5u) << "header + vertices + faces";
  EXPECT_EQ(lines[21], "4 0 3 2 1") << "first face";
  EXPECT_EQ(lines[25], "3 3 0 4") << "last face";
  ExpectMeshioReads(path,
                    "--points 5 --cells quad=1,triangle=4 --point-data stiffness,displacement_x,uv_1 "
                    "--point-data-sum stiffness=15,displacement_z=1.25");
}

TEST(SurfaceWritersTest, RejectInconsistentSurfaces) {
  ScopedTempDir tmp;
  const std::string dir = tmp.path();
  mesh::BoundarySurface bad_index = PyramidSurface();
  bad_index.faces.items[2] = 7;
  EXPECT_THAT(WriteObj(dir + "/a.obj", bad_index),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("surface face 0 refers to vertex 7: expected 0 to 4")));
  EXPECT_FALSE(std::filesystem::exists(dir + "/a.obj")) << "nothing written on error";

  mesh::BoundarySurface bad_field = PyramidSurface();
  bad_field.fields.push_back({"stiffness", 1, {1, 2, 3}});
  EXPECT_THAT(WritePly(dir + "/b.ply", bad_field),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("field 'stiffness' has 3 values: expected 5 vertices x 1")));

  mesh::BoundarySurface bad_name = PyramidSurface();
  bad_name.fields.push_back({"von mises", 1, std::vector<double>(5, 0.0)});
  EXPECT_THAT(WritePly(dir + "/c.ply", bad_name),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("without spaces")));

  mesh::BoundarySurface big_face;
  big_face.positions.setZero(300, 3);
  for (int32_t i = 0; i < 300; ++i) big_face.faces.items.push_back(i);
  big_face.faces.offsets.push_back(300);
  EXPECT_THAT(WritePly(dir + "/d.ply", big_face),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("surface face 0 has 300 vertices: expected 3 to 255")));
  EXPECT_OK(WriteObj(dir + "/d.obj", big_face)) << "OBJ has no face size limit";
}

TEST(SurfaceWritersTest, MissingDirectoryIsNotFound) {
  EXPECT_THAT(WriteObj("/nonexistent/dir/a.obj", PyramidSurface()),
              StatusIs(absl::StatusCode::kNotFound,
                       HasSubstr("/nonexistent/dir/a.obj: cannot open for writing")));
  EXPECT_THAT(WritePly("/nonexistent/dir/a.ply", PyramidSurface()),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("cannot open for writing")));
}

// The mixed mesh of scenes/meshes/mixed.vtk as a VolumeMesh, with data.
VolumeMesh MixedVolumeMesh() {
  VolumeMesh m;
  m.points.resize(12, 3);
  m.points << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1, 0.5, 0.5, 1.6,
      1.8, 0, 0.5, 1.8, 1, 0.5, 1.3, -0.6, 0.5;
  m.types = {12, 14, 13, 10};
  m.connectivity = {0, 1, 2, 3, 4, 5, 6, 7, 4, 5, 6, 7, 8, 1, 9, 5, 2, 10, 6, 1, 9, 5, 11};
  m.offsets = {8, 13, 19, 23};
  m.cell_data.push_back({"material", 1, {0, 1, 2, 3}, true});
  m.cell_data.push_back({"volume", 1, {1.0, 0.2, 0.4, 0.08}, false});
  m.cell_data.push_back({"gradient", 3, std::vector<double>(12, 0.5), false});
  std::vector<double> temperature(12);
  for (int i = 0; i < 12; ++i) temperature[i] = 0.1 * i;
  m.point_data.push_back({"temperature", 1, temperature, false});
  return m;
}

TEST(VtuWriterTest, MeshioReadsTheMixedMesh) {
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/mixed.vtu";
  ASSERT_OK(WriteVtu(path, MixedVolumeMesh()));
  const std::string text = ReadTextFile(path);
  EXPECT_THAT(text, HasSubstr("<VTKFile type=\"UnstructuredGrid\" version=\"1.0\""));
  EXPECT_THAT(text, HasSubstr("<DataArray type=\"Int64\" Name=\"connectivity\""));
  EXPECT_THAT(text, HasSubstr("<DataArray type=\"UInt8\" Name=\"types\""));
  EXPECT_THAT(text, HasSubstr("<DataArray type=\"Int32\" Name=\"material\""));
  ExpectMeshioReads(path,
      "--points 12 --point-sum 21.4 --cells hexahedron=1,pyramid=1,wedge=1,tetra=1 "
      "--cell-data material,volume,gradient --point-data temperature "
      "--cell-data-sum material=6,volume=1.68,gradient=6 --point-data-sum temperature=6.6");
}

TEST(VtuWriterTest, RejectsInconsistentMeshes) {
  ScopedTempDir tmp;
  const std::string dir = tmp.path();
  struct Case {
    std::string what;
    VolumeMesh mesh;
    std::string message;
  };
  std::vector<Case> cases;
  {
    VolumeMesh m = MixedVolumeMesh();
    m.offsets.pop_back();
    cases.push_back({"offsets", m, "3 offsets: expected one per cell, 4"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.offsets[3] = 22;
    cases.push_back({"last offset", m, "the last offset is 22: expected the connectivity size 23"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.connectivity[5] = 12;
    cases.push_back({"point id", m, "connectivity entry 5 is 12: expected 0 to 11"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.types[0] = 42;
    cases.push_back({"polyhedron", m, "cell 0 is a polyhedron (42)"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.points(3, 1) = std::numeric_limits<double>::quiet_NaN();
    cases.push_back({"nan point", m, "point 3 is not finite"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.cell_data[0].values[2] = 2.5;
    cases.push_back(
        {"integer", m, "cell data array 'material' value 2 = 2.5 is not a 32-bit integer"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.cell_data[1].name = "material";
    cases.push_back({"duplicate name", m, "cell data array 'material' appears twice"});
  }
  {
    VolumeMesh m = MixedVolumeMesh();
    m.point_data[0].values.pop_back();
    cases.push_back({"point data size", m,
                     "point data array 'temperature' has 11 values: expected 12 tuples x 1"});
  }
  for (const Case& c : cases) {
    const std::string path = dir + "/" + c.what + ".vtu";
    EXPECT_THAT(WriteVtu(path, c.mesh),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(c.message)))
        << c.what;
    EXPECT_FALSE(std::filesystem::exists(path)) << c.what << ": nothing written on error";
  }
}

// One cubic element over a 4x4x4 block of nodes (numbered in a scrambled
// order, at integer positions (i, j, k)), one linear hexahedron and one
// pyramid with a virtual apex.
struct ElementFixture {
  Points nodes;
  fem::ElementSet elements;
};

ElementFixture MakeElements() {
  ElementFixture f;
  f.nodes.resize(77, 3);
  f.elements.cubic_nodes.resize(64);
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      for (int k = 0; k < 4; ++k) {
        const int m = 16 * i + 4 * j + k;
        const int node = (37 * m) % 64;  // 37 is odd: a permutation of 0..63
        f.elements.cubic_nodes[m] = node;
        f.nodes.row(node) << i, j, k;
      }
    }
  }
  f.elements.cubic_cell = {7};
  const double cube[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                             {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  for (int n = 0; n < 8; ++n) {
    f.nodes.row(64 + n) << 5 + cube[n][0], cube[n][1], cube[n][2];
    f.elements.linear_nodes.push_back(64 + n);
  }
  f.elements.linear_cell = {3};
  for (int n = 0; n < 4; ++n) {
    f.nodes.row(72 + n) << 8 + cube[n][0], cube[n][1], 0;
    f.elements.pyramid_nodes.push_back(72 + n);
  }
  f.nodes.row(76) << 8.5, 0.5, 0.5;
  f.elements.pyramid_nodes.push_back(76);
  f.elements.pyramid_cell = {5};
  f.elements.virtual_node_cell = {5};
  f.elements.num_mesh_vertices = 76;
  f.elements.num_virtual_nodes = 1;
  return f;
}

TEST(ElementsToVolumeMeshTest, OneVtkCellPerElement) {
  const ElementFixture f = MakeElements();
  const std::vector<int32_t> control = {0, 0, 1, 1, 2, 2, 3, 3};
  const VolumeMesh m = ElementsToVolumeMesh(f.nodes, f.elements, control, 2);
  EXPECT_EQ(m.points, f.nodes);
  EXPECT_THAT(m.types, ElementsAre(12, 12, 14));
  EXPECT_THAT(m.offsets, ElementsAre(8, 16, 21));
  // The cubic element's hexahedron: its cell's corners (1..2)^3 in VTK
  // order, so right-handed with positive volume.
  const double expected[8][3] = {{1, 1, 1}, {2, 1, 1}, {2, 2, 1}, {1, 2, 1},
                                 {1, 1, 2}, {2, 1, 2}, {2, 2, 2}, {1, 2, 2}};
  for (int n = 0; n < 8; ++n) {
    EXPECT_EQ(m.points.row(m.connectivity[n]),
              Eigen::RowVector3d(expected[n][0], expected[n][1], expected[n][2]))
        << "corner " << n << " of the cubic element";
  }
  EXPECT_THAT(std::vector<int64_t>(m.connectivity.begin() + 8, m.connectivity.end()),
              ElementsAre(64, 65, 66, 67, 68, 69, 70, 71, 72, 73, 74, 75, 76));
  ASSERT_EQ(m.cell_data.size(), 4u);
  EXPECT_EQ(m.cell_data[0].name, "element_kind");
  EXPECT_THAT(m.cell_data[0].values, ElementsAre(0, 1, 2));
  EXPECT_EQ(m.cell_data[1].name, "cell");
  EXPECT_THAT(m.cell_data[1].values, ElementsAre(7, 3, 5));
  EXPECT_EQ(m.cell_data[2].name, "control_cell");
  EXPECT_THAT(m.cell_data[2].values, ElementsAre(3, 1, 2));
  EXPECT_EQ(m.cell_data[3].name, "level");
  EXPECT_THAT(m.cell_data[3].values, ElementsAre(2, 2, 2));
  for (const DataArray& a : m.cell_data) EXPECT_TRUE(a.integer) << a.name;

  const VolumeMesh no_map = ElementsToVolumeMesh(f.nodes, f.elements, {}, 0);
  EXPECT_THAT(no_map.cell_data[2].values, ElementsAre(7, 3, 5))
      << "without a map, control_cell is the cell";

  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/elements.vtu";
  ASSERT_OK(WriteVtu(path, m));
  ExpectMeshioReads(path, "--points 77 --cells hexahedron=2,pyramid=1 "
                          "--cell-data element_kind,cell,control_cell,level "
                          "--cell-data-sum element_kind=3,cell=15,control_cell=6,level=6");
}

}  // namespace
}  // namespace dynsolid::io
