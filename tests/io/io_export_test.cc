// Tests of the binary export writers (STL, binary PLY): every file is read
// back byte by byte here (layout, counts, normals, enclosed volume), and by
// an independent reader (meshio through tests/io/read_vtu.py and Debian's
// /usr/bin/python3).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "solver/io/surface_writers.h"
#include "tests/io/export_surfaces.h"
#include "tests/io/io_test_util.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::io {
namespace {

using ::dynsolid::testing::StatusIs;
using testing::F32At;
using testing::F64At;
using ::testing::HasSubstr;
using testing::ReadTextFile;
using testing::ExpectMeshioReads;
using testing::ScopedTempDir;
using testing::U16At;
using testing::U32At;
using testing::Vec3At;

struct StlTriangle {
  Eigen::Vector3d normal;
  Eigen::Vector3d v[3];
  uint16_t attribute = 0;
};

// Reads a binary STL byte by byte: header, count, 50-byte records.
std::vector<StlTriangle> ReadStl(const std::string& bytes, std::string* header) {
  std::vector<StlTriangle> triangles;
  if (bytes.size() < 84) {
    ADD_FAILURE() << "STL of " << bytes.size() << " bytes: shorter than its 84-byte preamble";
    return triangles;
  }
  *header = bytes.substr(0, 80);
  const uint32_t count = U32At(bytes, 80);
  if (bytes.size() != 84 + 50 * static_cast<size_t>(count)) {
    ADD_FAILURE() << "STL of " << bytes.size() << " bytes for " << count
                  << " triangles: expected 84 + 50 per triangle";
    return triangles;
  }
  for (uint32_t t = 0; t < count; ++t) {
    const size_t at = 84 + 50 * static_cast<size_t>(t);
    StlTriangle tri;
    tri.normal = Vec3At(bytes, at);
    for (int k = 0; k < 3; ++k) tri.v[k] = Vec3At(bytes, at + 12 + 12 * k);
    tri.attribute = U16At(bytes, at + 48);
    triangles.push_back(tri);
  }
  return triangles;
}

// x rounded to float32. Through a volatile: Debian's GCC 12 at -O2/-O3
// vectorizes (double)(float) of neighbouring coordinates into no rounding
// at all, so the plain cast does not round here.
double RoundToFloat(double x) {
  volatile float f = static_cast<float>(x);
  return f;
}

// Vertex v's position rounded to float32.
Eigen::Vector3d FloatPosition(const mesh::BoundarySurface& s, int32_t v) {
  return {RoundToFloat(s.positions(v, 0)), RoundToFloat(s.positions(v, 1)),
          RoundToFloat(s.positions(v, 2))};
}

// Checks the triangles against the surface: the fans of its loops in face
// order (positions as float32), unit normals from the winding, pointing
// away from `centre` (the surfaces here are convex), attribute 0. Returns
// the enclosed volume (divergence theorem over the file's triangles).
double CheckStlTriangles(const std::vector<StlTriangle>& triangles, const mesh::BoundarySurface& s,
                         const Eigen::Vector3d& centre) {
  size_t t = 0;
  double six_v = 0.0;
  for (int32_t f = 0; f < s.faces.rows(); ++f) {
    const auto loop = s.faces.row(f);
    for (size_t i = 1; i + 1 < loop.size(); ++i, ++t) {
      if (t >= triangles.size()) {
        ADD_FAILURE() << "the STL ends at triangle " << t << " (face " << f << ")";
        return 0.0;
      }
      const StlTriangle& tri = triangles[t];
      EXPECT_EQ(tri.v[0], FloatPosition(s, loop[0])) << "triangle " << t;
      EXPECT_EQ(tri.v[1], FloatPosition(s, loop[i])) << "triangle " << t;
      EXPECT_EQ(tri.v[2], FloatPosition(s, loop[i + 1])) << "triangle " << t;
      EXPECT_NEAR(tri.normal.norm(), 1.0, 1e-6) << "triangle " << t << ": normal not unit";
      const Eigen::Vector3d winding = (tri.v[1] - tri.v[0]).cross(tri.v[2] - tri.v[0]).normalized();
      EXPECT_GT(tri.normal.dot(winding), 1.0 - 1e-5)
          << "triangle " << t << ": normal " << tri.normal.transpose() << " is not its winding's "
          << winding.transpose();
      const Eigen::Vector3d middle = (tri.v[0] + tri.v[1] + tri.v[2]) / 3.0;
      EXPECT_GT(tri.normal.dot(middle - centre), 0.0)
          << "triangle " << t << " at " << middle.transpose() << ": normal "
          << tri.normal.transpose() << " points inward";
      EXPECT_EQ(tri.attribute, 0) << "triangle " << t;
      six_v += tri.v[0].dot(tri.v[1].cross(tri.v[2]));
    }
  }
  EXPECT_EQ(t, triangles.size()) << "triangles beyond the loops' fans";
  return six_v / 6.0;
}

TEST(StlWriterTest, CubeTrianglesNormalsAndVolume) {
  const mesh::BoundarySurface cube = testing::CubeSurface(2.0);
  ASSERT_EQ(cube.faces.rows(), 6);
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/cube.stl";
  ASSERT_OK(WriteStlBinary(path, cube));
  const std::string bytes = ReadTextFile(path);

  std::string in_memory = "prefix";
  ASSERT_OK(StlBinaryBytes(cube, &in_memory));
  EXPECT_TRUE(in_memory == "prefix" + bytes) << "StlBinaryBytes appends the file's bytes";

  std::string header;
  const std::vector<StlTriangle> triangles = ReadStl(bytes, &header);
  EXPECT_EQ(triangles.size(), 12u) << "6 quads, 2 triangles each";
  EXPECT_EQ(header.rfind("solid", 0), std::string::npos)
      << "a binary STL header must not start with 'solid': " << header;
  EXPECT_EQ(header.rfind("dynsolid boundary surface", 0), 0u) << header;
  const double volume = CheckStlTriangles(triangles, cube, Eigen::Vector3d(1, 1, 1));
  EXPECT_NEAR(volume, 8.0, 1e-12) << "volume enclosed by the STL's triangles";
  for (const StlTriangle& tri : triangles) {
    EXPECT_NEAR(tri.normal.cwiseAbs().maxCoeff(), 1.0, 1e-7)
        << "a cube's facet normal is an axis: " << tri.normal.transpose();
  }
  ExpectMeshioReads(path, "--points 8 --point-sum 24 --cells triangle=12");
}

TEST(StlWriterTest, SubdividedBlockIsClosedAndOutward) {
  const testing::SubdividedBlock block = testing::SubdividedBlockSurface(2);
  const mesh::BoundarySurface& s = block.surface;
  ASSERT_GT(s.faces.rows(), 24);
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/block.stl";
  ASSERT_OK(WriteStlBinary(path, s));
  std::string header;
  const std::vector<StlTriangle> triangles = ReadStl(ReadTextFile(path), &header);
  EXPECT_EQ(static_cast<int64_t>(triangles.size()), testing::FanTriangles(s));
  const double volume = CheckStlTriangles(triangles, s, Eigen::Vector3d(1, 1, 1));
  EXPECT_NEAR(volume, testing::FanVolume(s), 1e-5 * testing::FanVolume(s))
      << "float32 STL against the double fans";
  EXPECT_NEAR(volume, block.cell_volume, 1e-3 * block.cell_volume)
      << "the surface encloses the fine cells (their curved faces fanned otherwise)";
  EXPECT_LT(volume, 8.0) << "subdivision rounds the 2x2x2 block";
  ExpectMeshioReads(path, "--points " + std::to_string(s.positions.rows()) +
                          " --cells triangle=" + std::to_string(testing::FanTriangles(s)));
}

// A pyramid's boundary (a quad and four triangles) with fields of 1, 3 and
// 2 components.
mesh::BoundarySurface PyramidWithFields() {
  absl::StatusOr<mesh::CellComplex> pyramid =
      mesh::CellComplex::FromInput(dynsolid::testing::Pyramid());
  EXPECT_TRUE(pyramid.ok()) << pyramid.status();
  mesh::BoundarySurface s = mesh::ExtractBoundary(*pyramid);
  testing::AddFields(s);
  mesh::VertexField uv{"uv", 2, {}};
  for (int64_t i = 0; i < s.positions.rows(); ++i) {
    uv.values.push_back(0.1 * static_cast<double>(i));
    uv.values.push_back(-1e-3 / (1.0 + static_cast<double>(i)));
  }
  s.fields.push_back(std::move(uv));
  return s;
}

// The PLY property names of the surface's fields, component by component.
std::vector<std::string> PlyFieldNames(const mesh::VertexField& f) {
  std::vector<std::string> names;
  for (int k = 0; k < f.components; ++k) {
    names.push_back(f.components == 1   ? f.name
                    : f.components == 3 ? f.name + "_" + std::string(1, static_cast<char>('x' + k))
                                        : f.name + "_" + std::to_string(k));
  }
  return names;
}

// The arrays read_vtu.py --expect-arrays compares the file with.
std::string ExpectedArraysJson(const mesh::BoundarySurface& s) {
  auto number = [](double v) {
    char tmp[40];
    std::snprintf(tmp, sizeof(tmp), "%.17g", v);
    return std::string(tmp);
  };
  std::string j = "{\"points\": [";
  for (int64_t i = 0; i < s.positions.rows(); ++i) {
    j += (i > 0 ? ", [" : "[") + number(s.positions(i, 0)) + ", " + number(s.positions(i, 1)) +
         ", " + number(s.positions(i, 2)) + "]";
  }
  j += "], \"point_data\": {";
  bool first = true;
  for (const mesh::VertexField& f : s.fields) {
    const std::vector<std::string> names = PlyFieldNames(f);
    for (int k = 0; k < f.components; ++k) {
      j += (first ? "\"" : ", \"") + names[k] + "\": [";
      first = false;
      for (int64_t i = 0; i < s.positions.rows(); ++i) {
        j += (i > 0 ? ", " : "") + number(f.values[i * f.components + k]);
      }
      j += "]";
    }
  }
  j += "}, \"faces\": [";
  for (int32_t r = 0; r < s.faces.rows(); ++r) {
    j += r > 0 ? ", [" : "[";
    for (size_t i = 0; i < s.faces.row(r).size(); ++i) {
      j += (i > 0 ? ", " : "") + std::to_string(s.faces.row(r)[i]);
    }
    j += "]";
  }
  return j + "]}\n";
}

// Writes `s` as binary PLY, reads it back byte by byte and with meshio.
void CheckBinaryPly(const mesh::BoundarySurface& s, const std::string& name) {
  ScopedTempDir tmp;
  const std::string path = tmp.path() + "/" + name + ".ply";
  ASSERT_OK(WritePlyBinary(path, s));
  const std::string bytes = ReadTextFile(path);
  std::string in_memory;
  ASSERT_OK(PlyBinaryBytes(s, &in_memory));
  EXPECT_TRUE(in_memory == bytes) << "PlyBinaryBytes gives the file's bytes";

  // The header is the ASCII writer's with the binary format line.
  std::string ascii;
  ASSERT_OK(PlyBytes(s, &ascii));
  std::string header = ascii.substr(0, ascii.find("end_header\n") + 11);
  header.replace(header.find("format ascii 1.0"), 16, "format binary_little_endian 1.0");
  ASSERT_EQ(bytes.substr(0, header.size()), header);

  size_t at = header.size();
  size_t record = 24;
  for (const mesh::VertexField& f : s.fields) record += 4 * static_cast<size_t>(f.components);
  ASSERT_GE(bytes.size(), at + record * static_cast<size_t>(s.positions.rows()));
  for (int64_t i = 0; i < s.positions.rows(); ++i) {
    for (int k = 0; k < 3; ++k, at += 8) {
      EXPECT_EQ(F64At(bytes, at), s.positions(i, k)) << "vertex " << i << " coordinate " << k;
    }
    for (const mesh::VertexField& f : s.fields) {
      for (int k = 0; k < f.components; ++k, at += 4) {
        EXPECT_EQ(F32At(bytes, at), static_cast<float>(f.values[i * f.components + k]))
            << "field " << f.name << " vertex " << i << " component " << k;
      }
    }
  }
  for (int32_t r = 0; r < s.faces.rows(); ++r) {
    ASSERT_LT(at, bytes.size()) << "face " << r;
    EXPECT_EQ(static_cast<uint8_t>(bytes[at]), s.faces.row_size(r)) << "face " << r << " size";
    ++at;
    for (int32_t v : s.faces.row(r)) {
      ASSERT_LE(at + 4, bytes.size());
      EXPECT_EQ(static_cast<int32_t>(U32At(bytes, at)), v) << "face " << r;
      at += 4;
    }
  }
  EXPECT_EQ(at, bytes.size()) << "bytes after the last face";

  const std::string expect = tmp.path() + "/" + name + ".expect.json";
  testing::WriteTextFile(expect, ExpectedArraysJson(s));
  ExpectMeshioReads(
      path, "--points " + std::to_string(s.positions.rows()) + " --expect-arrays '" + expect + "'");
}

TEST(PlyBinaryWriterTest, PyramidWithFieldsRoundTripsThroughMeshio) {
  CheckBinaryPly(PyramidWithFields(), "pyramid");
}

TEST(PlyBinaryWriterTest, SubdividedBlockRoundTripsThroughMeshio) {
  testing::SubdividedBlock block = testing::SubdividedBlockSurface(1);
  testing::AddFields(block.surface);
  CheckBinaryPly(block.surface, "block");
}

TEST(SurfaceWritersTest, BytesVariantsGiveTheFilesBytes) {
  const mesh::BoundarySurface s = PyramidWithFields();
  ScopedTempDir tmp;
  ASSERT_OK(WriteObj(tmp.path() + "/a.obj", s));
  ASSERT_OK(WritePly(tmp.path() + "/a.ply", s));
  std::string obj = "x";
  std::string ply;
  ASSERT_OK(ObjBytes(s, &obj));
  ASSERT_OK(PlyBytes(s, &ply));
  EXPECT_EQ(obj, "x" + ReadTextFile(tmp.path() + "/a.obj"));
  EXPECT_EQ(ply, ReadTextFile(tmp.path() + "/a.ply"));
}

// `write` refuses case c's surface with its message after `path`, writing
// no `format` file; `to_bytes` refuses it too, appending nothing.
template <typename Case>
void ExpectRefusedSurface(absl::Status (*write)(const std::string&, const mesh::BoundarySurface&),
                          absl::Status (*to_bytes)(const mesh::BoundarySurface&, std::string*),
                          const std::string& path, const char* format, const Case& c) {
  std::string bytes = "kept";
  EXPECT_THAT(write(path, c.surface),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(path + ": " + c.message)))
      << c.what;
  EXPECT_FALSE(std::filesystem::exists(path)) << c.what << ": no " << format << " file on error";
  EXPECT_THAT(to_bytes(c.surface, &bytes),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr(c.message)));
  EXPECT_EQ(bytes, "kept") << c.what << ": nothing appended on error";
}

// Each binary writer refuses a bad surface with a message naming the vertex
// or face, writes no file and appends nothing.
TEST(SurfaceWritersTest, BinaryWritersRefuseBadSurfaces) {
  struct Case {
    std::string what;
    mesh::BoundarySurface surface;
    std::string message;
    bool stl = true;  // refused by the STL writer
    bool ply = true;  // refused by the binary PLY writer
  };
  std::vector<Case> cases;
  const mesh::BoundarySurface cube = testing::CubeSurface(1.0);
  {
    mesh::BoundarySurface s = cube;
    s.positions(2, 1) = std::numeric_limits<double>::quiet_NaN();
    cases.push_back({"nan", s, "surface vertex 2 has a non-finite coordinate y (nan)"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.positions(7, 2) = -std::numeric_limits<double>::infinity();
    cases.push_back({"inf", s, "surface vertex 7 has a non-finite coordinate z (-inf)"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.faces.items[s.faces.offsets[3] + 1] = 8;
    cases.push_back({"index", s, "surface face 3 refers to vertex 8: expected 0 to 7"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.faces.items[0] = -1;
    cases.push_back({"negative index", s, "surface face 0 refers to vertex -1: expected 0 to 7"});
  }
  {
    mesh::BoundarySurface s = cube;
    s.faces = mesh::Csr{};
    cases.push_back({"no faces", s, "surface has no faces (8 vertices)", true, false});
  }
  {
    mesh::BoundarySurface s = cube;
    s.positions(4, 0) = 1e300;
    cases.push_back(
        {"float32", s, "surface vertex 4 has coordinate x = 1e+300, beyond float32", true, false});
  }
  {
    mesh::BoundarySurface s = cube;
    s.fields.push_back({"stiffness", 1, {1, 2, 3}});
    cases.push_back({"field", s, "field 'stiffness' has 3 values: expected 8 vertices x 1"});
  }
  ScopedTempDir tmp;
  for (const Case& c : cases) {
    const std::string stl = tmp.path() + "/" + c.what + ".stl";
    const std::string ply = tmp.path() + "/" + c.what + ".ply";
    if (c.stl) {
      ExpectRefusedSurface(WriteStlBinary, StlBinaryBytes, stl, "STL", c);
    } else {
      EXPECT_OK(WriteStlBinary(stl, c.surface)) << c.what;
    }
    if (c.ply) {
      ExpectRefusedSurface(WritePlyBinary, PlyBinaryBytes, ply, "PLY", c);
    } else {
      EXPECT_OK(WritePlyBinary(ply, c.surface)) << c.what << ": PLY stores doubles, any count";
    }
  }
}

TEST(SurfaceWritersTest, BinaryWritersMissingDirectoryIsNotFound) {
  const mesh::BoundarySurface cube = testing::CubeSurface(1.0);
  EXPECT_THAT(WriteStlBinary("/nonexistent/dir/a.stl", cube),
              StatusIs(absl::StatusCode::kNotFound,
                       HasSubstr("/nonexistent/dir/a.stl: cannot open for writing")));
  EXPECT_THAT(WritePlyBinary("/nonexistent/dir/a.ply", cube),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("cannot open for writing")));
}

}  // namespace
}  // namespace dynsolid::io
