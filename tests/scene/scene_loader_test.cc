#include "solver/scene/scene_loader.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <string>

#include <unistd.h>

#include <google/protobuf/util/message_differencer.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "solver/mesh/cell_complex.h"
#include "tests/scene/mesh_input_checks.h"
#include "tests/scene/scene_test_support.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::scene {
namespace {

fs::path ScenesDir() { return SourceDir() / "scenes"; }

// A scratch folder for files the tests write, removed at the end.
class TempDir {
 public:
  TempDir() {
    const char* base = std::getenv("TEST_TMPDIR");
    path_ = (base != nullptr ? fs::path(base) : fs::temp_directory_path()) /
            ("dynsolid_scene_test_" + std::to_string(::getpid()));
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }
  fs::path Write(const std::string& name, const std::string& text) const {
    const fs::path p = path_ / name;
    std::ofstream(p) << text;
    return p;
  }

 private:
  fs::path path_;
};

// Control cell counts of the example scenes (the mixed mesh is whatever
// scenes/meshes/mixed.vtk holds: only checked to build).
struct SceneFacts {
  int64_t cells;
  int64_t vertices;
  int64_t boundary_euler;
};
const std::map<std::string, SceneFacts>& ExpectedScenes() {
  static const auto* facts = new std::map<std::string, SceneFacts>{
      {"block3", {27, 64, 2}},   {"block4", {64, 125, 2}},  {"chair", {76, 220, 2}},
      {"bridge", {154, 392, -2}}, {"nozzle", {99, 220, 0}}, {"torus", {48, 108, 0}},
      {"beam", {10, 44, 2}},     {"mixed", {-1, -1, 2}},   {"clay", {48, 100, 2}},
  };
  return *facts;
}

TEST(SceneFilesTest, EverySceneFileLoadsBuildsAndMatchesItsBuiltin) {
  std::set<std::string> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(ScenesDir())) {
    if (entry.path().extension() != ".textproto") continue;
    const std::string stem = entry.path().stem().string();
    files.insert(stem);
    SCOPED_TRACE(entry.path().string());

    absl::StatusOr<Scene> scene = LoadSceneFile(entry.path().string());
    ASSERT_OK(scene);
    EXPECT_EQ(scene->name(), stem) << "a scene's name is its file stem";
    EXPECT_FALSE(scene->description().empty());
    EXPECT_THAT(scene->description(), HasSubstr("Table 1"));
    EXPECT_EQ(scene->subdivision().levels(), 2);

    absl::StatusOr<Scene> builtin = BuiltinScene(stem);
    ASSERT_OK(builtin);
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(*scene, *builtin))
        << "built-in scene " << stem << " differs from its file";

    absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, ScenesDir().string());
    ASSERT_OK(input);
    EXPECT_OK(testing::CheckMeshInput(*input));
    EXPECT_EQ(testing::CountComponents(*input), 1);
    absl::StatusOr<mesh::CellComplex> complex = mesh::CellComplex::FromInput(*input);
    ASSERT_OK(complex);
    for (int32_t c = 0; c < complex->num_cells(); ++c) {
      EXPECT_GT(complex->CellVolume(c), 0) << "cell " << c;
    }
    const auto it = ExpectedScenes().find(stem);
    ASSERT_NE(it, ExpectedScenes().end()) << "add " << stem << " to ExpectedScenes()";
    if (it->second.cells >= 0) {
      EXPECT_EQ(complex->num_cells(), it->second.cells) << "control cells";
      EXPECT_EQ(complex->num_vertices(), it->second.vertices) << "control vertices";
    }
    EXPECT_EQ(complex->CountBoundary().euler(), it->second.boundary_euler)
        << "boundary Euler characteristic";
  }
  // Every example scene is built in, and every built-in has its file.
  const std::vector<std::string> names = BuiltinSceneNames();
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()), files);
  for (const auto& [name, facts] : ExpectedScenes()) EXPECT_TRUE(files.contains(name)) << name;
}

TEST(BuiltinSceneTest, DefaultSceneIsBlock3) {
  ASSERT_FALSE(BuiltinSceneNames().empty());
  EXPECT_EQ(BuiltinSceneNames().front(), "block3");
  absl::StatusOr<Scene> scene = BuiltinScene("block3");
  ASSERT_OK(scene);
  EXPECT_EQ(scene->mesh().block().nx(), 3);
  absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, "");
  ASSERT_OK(input);
  EXPECT_EQ(input->cells.size(), 27u);
  EXPECT_EQ(input->vertices.rows(), 64);
  EXPECT_THAT(input->origin, StartsWith("scene block3"));
}

TEST(BuiltinSceneTest, UnknownNameListsTheKnownOnes) {
  EXPECT_THAT(BuiltinScene("blok3"),
              StatusIs(absl::StatusCode::kNotFound,
                       AllOf(HasSubstr("blok3"), HasSubstr("block3, block4, chair"))));
}

TEST(SceneDocTest, TheCompleteExampleInDocsLoadsAndBuilds) {
  std::ifstream in(SourceDir() / "docs" / "scene.md");
  ASSERT_TRUE(in) << "docs/scene.md";
  const std::string doc((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string open = "```textproto\n";
  const size_t begin = doc.find(open);
  ASSERT_NE(begin, std::string::npos) << "no textproto block in docs/scene.md";
  const size_t end = doc.find("```", begin + open.size());
  ASSERT_NE(end, std::string::npos);
  absl::StatusOr<Scene> scene =
      ParseScene(doc.substr(begin + open.size(), end - begin - open.size()), "docs/scene.md");
  ASSERT_OK(scene);
  absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, "");
  ASSERT_OK(input);
  EXPECT_EQ(input->cells.size(), 76u);
  EXPECT_OK(mesh::CellComplex::FromInput(*input));
}

// ------------------------------------------------------------ ParseScene

TEST(ParseSceneTest, SyntaxErrorReportsOriginLineAndColumn) {
  // Protobuf reports an unknown field at the token after its name (the "{").
  const std::string text =
      "name: \"x\"\n"
      "mesh { blok { nx: 3 } }\n";
  EXPECT_THAT(ParseScene(text, "bad.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(StartsWith("bad.textproto:2:13: "), HasSubstr("blok"))));

  EXPECT_THAT(ParseScene("name: \"x\"\nsubdivision { levels: two }\n", "s.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument, StartsWith("s.textproto:2:23: ")));
  EXPECT_THAT(ParseScene("mesh { block { nx: 3 ny: 3 nz: 3 }\n", "open.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument, StartsWith("open.textproto:2:")));
}

TEST(ParseSceneTest, InvalidFieldReportsItsPositionAndPath) {
  const std::string text =
      "name: \"nozzle\"\n"
      "mesh {\n"
      "  tube {\n"
      "    segments: 11 layers: 1 slices: 9\n"
      "    inner_radius: 2\n"
      "    outer_radius: 1\n"
      "    length: 1\n"
      "  }\n"
      "}\n";
  EXPECT_THAT(ParseScene(text, "t.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(StartsWith("t.textproto:5:5: "),
                             HasSubstr("mesh.tube.inner_radius (2) must be less than "
                                       "tube.outer_radius (1)"))));
  // A missing field is reported at its closest enclosing field.
  EXPECT_THAT(ParseScene("mesh {\n  block { nx: 3 ny: 3 }\n}\n", "b.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("b.textproto:2:3: mesh.block.nz must be >= 1, got 0")));
  EXPECT_THAT(
      ParseScene("mesh { voxels {\n boxes { x1: 1 y1: 1 z1: 1 }\n boxes { x0: 4 x1: 2 y1: 1 z1: 1 } } }\n",
                 "v.textproto"),
      StatusIs(absl::StatusCode::kInvalidArgument,
               StartsWith("v.textproto:3:16: mesh.voxels.boxes[1].x1 (2) must be greater than")));
}

TEST(ParseSceneTest, RejectsBadSceneFields) {
  const std::string block = "mesh { block { nx: 1 ny: 1 nz: 1 } } ";
  const std::pair<std::string, std::string> cases[] = {
      {"name: \"empty\"", "mesh.source is not set"},
      {"mesh { scale: 2 }", "mesh.source is not set"},
      {"mesh { file: \"\" }", "mesh.file is empty"},
      {block + "subdivision { levels: 5 }", "subdivision.levels must be in 0..4, got 5"},
      {block + "subdivision { levels: -1 }", "subdivision.levels must be in 0..4, got -1"},
      {block + "sharp { crease_angle_degrees: 200 }",
       "sharp.crease_angle_degrees must be in [0, 180] (0 = off), got 200"},
      {block + "sharp { crease_angle_degrees: -1 }", "sharp.crease_angle_degrees must be in"},
      {block + "sharp { crease_angle_degrees: nan }",
       "sharp.crease_angle_degrees must be finite, got nan"},
      {block + "sharp { edges { v0: -1 v1: 2 } }",
       "sharp.edges[0].v0 must be a vertex index >= 0, got -1"},
      {block + "sharp { edges { v0: 0 v1: 1 } edges { v0: 3 v1: 3 } }",
       "sharp.edges[1] joins vertex 3 to itself"},
      {"mesh { block { nx: 1 ny: 1 nz: 1 } refine_cells: 0 refine_cells: -3 }",
       "mesh.refine_cells[1] must be a cell index >= 0, got -3"},
      {"mesh { block { nx: 1 ny: 1 nz: 1 } scale: -2 }",
       "mesh.scale must be > 0 (0 means 1), got -2"},
      {"mesh { block { nx: 1 ny: 1 nz: 1 } translate { y: inf } }",
       "mesh.translate.y must be finite"},
      {"mesh { beam { length: 1 width: 0.1 height: 0.1 cells_along: 0 cells_across: 1 } }",
       "mesh.beam.cells_along must be >= 1, got 0"},
      {"mesh { torus { major_radius: 1 tube_half_width: 2 segments: 12 cross: 2 } }",
       "mesh.torus.tube_half_width (2) must be less than torus.major_radius (1)"},
      {"mesh { voxels { } }", "mesh.voxels.boxes is empty"},
  };
  for (const auto& [text, message] : cases) {
    EXPECT_THAT(ParseScene(text, "case.textproto"),
                StatusIs(absl::StatusCode::kInvalidArgument,
                         AllOf(StartsWith("case.textproto:"), HasSubstr(message))))
        << text;
  }
}

// ------------------------------------------------------- ControlMeshInput

TEST(ControlMeshInputTest, AppliesScaleThenTranslate) {
  absl::StatusOr<Scene> scene = ParseScene(
      "name: \"moved\" mesh { block { nx: 3 ny: 3 nz: 3 } scale: 2 translate { x: 1 } }", "m");
  ASSERT_OK(scene);
  absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, "");
  ASSERT_OK(input);
  EXPECT_EQ(input->vertices.row(0), Eigen::RowVector3d(1, 0, 0));
  EXPECT_EQ(input->vertices.row(63), Eigen::RowVector3d(7, 6, 6));
}

TEST(ControlMeshInputTest, ChecksIndicesAgainstTheMesh) {
  absl::StatusOr<Scene> scene =
      ParseScene("name: \"b\" mesh { block { nx: 3 ny: 3 nz: 3 } refine_cells: 27 }", "r");
  ASSERT_OK(scene);
  EXPECT_THAT(ControlMeshInput(*scene, ""),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("scene b: mesh.refine_cells[0] (27) must be less than the "
                                 "number of control cells (27)")));
  scene = ParseScene(
      "name: \"b\" mesh { block { nx: 1 ny: 1 nz: 1 } } sharp { edges { v0: 0 v1: 8 } }", "e");
  ASSERT_OK(scene);
  EXPECT_THAT(ControlMeshInput(*scene, ""),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("sharp.edges[0].v1 (8) must be less than the number of "
                                 "control vertices (8)")));
}

TEST(ControlMeshInputTest, NoMeshSourceNamesTheField) {
  Scene scene;
  scene.set_name("nothing");
  EXPECT_THAT(ControlMeshInput(scene, ""),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("scene nothing: mesh.source is not set"),
                             HasSubstr("mesh.block"))));
}

TEST(ControlMeshInputTest, GeneratorResultErrorsNameTheField) {
  Scene scene;
  auto* voxels = scene.mutable_mesh()->mutable_voxels();
  auto* box = voxels->add_boxes();
  box->set_x1(1), box->set_y1(1), box->set_z1(1);
  box = voxels->add_boxes();
  box->set_x1(1), box->set_y1(1), box->set_z1(1), box->set_subtract(true);
  EXPECT_THAT(ControlMeshInput(scene, ""),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("mesh.voxels: no voxel remains")));
}

TEST(ControlMeshInputTest, MissingMeshFileIsNotFound) {
  absl::StatusOr<Scene> scene = ParseScene("name: \"f\" mesh { file: \"nope.vtk\" }", "f");
  ASSERT_OK(scene);
  EXPECT_THAT(ControlMeshInput(*scene, "/nonexistent_dir"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("nonexistent_dir/nope.vtk")));
}

// ------------------------------------------------------------ file loading

// One unit hexahedron in VTK legacy format.
constexpr char kOneHexVtk[] =
    "# vtk DataFile Version 3.0\n"
    "one hex\n"
    "ASCII\n"
    "DATASET UNSTRUCTURED_GRID\n"
    "POINTS 8 double\n"
    "0 0 0  1 0 0  1 1 0  0 1 0  0 0 1  1 0 1  1 1 1  0 1 1\n"
    "CELLS 1 9\n"
    "8 0 1 2 3 4 5 6 7\n"
    "CELL_TYPES 1\n"
    "12\n";

TEST(LoadSceneFileTest, MissingFileIsNotFound) {
  EXPECT_THAT(LoadSceneFile("/nonexistent_dir/scene.textproto"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("/nonexistent_dir/scene.textproto")));
}

TEST(LoadSceneFileTest, ErrorsNameThePath) {
  TempDir tmp;
  const fs::path p = tmp.Write("bad.textproto", "name: \"bad\"\nmesh { block { nx: 0 } }\n");
  EXPECT_THAT(LoadSceneFile(p.string()),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith(p.string() + ":2:16: mesh.block.nx must be >= 1, got 0")));
}

TEST(LoadSceneOrMeshTest, BuiltinName) {
  absl::StatusOr<LoadedScene> loaded = LoadSceneOrMesh("chair");
  ASSERT_OK(loaded);
  EXPECT_EQ(loaded->scene.name(), "chair");
  EXPECT_EQ(loaded->origin, "builtin:chair");
  EXPECT_EQ(loaded->base_dir, BuiltinSceneDir());
  EXPECT_OK(ControlMeshInput(loaded->scene, loaded->base_dir));
}

TEST(LoadSceneOrMeshTest, SceneFileResolvesMeshesNextToIt) {
  TempDir tmp;
  tmp.Write("hex.vtk", kOneHexVtk);
  const fs::path p = tmp.Write("s.textproto", "name: \"s\" mesh { file: \"hex.vtk\" scale: 3 }");
  absl::StatusOr<LoadedScene> loaded = LoadSceneOrMesh(p.string());
  ASSERT_OK(loaded);
  EXPECT_EQ(fs::path(loaded->base_dir), tmp.path());
  absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(loaded->scene, loaded->base_dir);
  ASSERT_OK(input);
  EXPECT_EQ(input->cells.size(), 1u);
  EXPECT_DOUBLE_EQ(input->vertices.maxCoeff(), 3.0);
  EXPECT_OK(mesh::CellComplex::FromInput(*input));
}

TEST(LoadSceneOrMeshTest, MeshFileAloneGetsADefaultScene) {
  TempDir tmp;
  const fs::path p = tmp.Write("cube.vtk", kOneHexVtk);
  absl::StatusOr<LoadedScene> loaded = LoadSceneOrMesh(p.string());
  ASSERT_OK(loaded);
  EXPECT_EQ(loaded->scene.name(), "cube");
  EXPECT_EQ(loaded->scene.subdivision().levels(), 2);
  EXPECT_EQ(loaded->scene.mesh().file(), "cube.vtk");
  EXPECT_OK(ValidateScene(loaded->scene));
  absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(loaded->scene, loaded->base_dir);
  ASSERT_OK(input);
  EXPECT_EQ(input->cells.size(), 1u);
}

TEST(LoadSceneOrMeshTest, UnknownArgumentsAreNotFound) {
  EXPECT_THAT(LoadSceneOrMesh("no_such_scene"),
              StatusIs(absl::StatusCode::kNotFound,
                       AllOf(HasSubstr("no_such_scene"), HasSubstr("block3"))));
  EXPECT_THAT(LoadSceneOrMesh("/nonexistent_dir/part.msh"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("part.msh")));
  EXPECT_THAT(LoadSceneOrMesh("/nonexistent_dir/s.textproto"),
              StatusIs(absl::StatusCode::kNotFound, HasSubstr("s.textproto")));
  EXPECT_THAT(LoadSceneOrMesh(""), StatusIs(absl::StatusCode::kInvalidArgument,
                                            HasSubstr("no scene given")));
}

}  // namespace
}  // namespace dynsolid::scene
