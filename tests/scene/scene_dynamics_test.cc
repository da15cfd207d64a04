// The dynamics part of the scene format: validation of materials, regions,
// loads, constraints, traced points and solver settings (with their
// origin:line:col positions), the defaults helpers, and the dynamics in the
// example scenes and in docs/scene.md.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/mesh/cell_complex.h"
#include "solver/scene/scene_loader.h"
#include "tests/scene/scene_test_support.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::scene {
namespace {

using ::google::protobuf::Descriptor;
using ::google::protobuf::FieldDescriptor;
using ::google::protobuf::Message;
using ::google::protobuf::Reflection;
using ::google::protobuf::TextFormat;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in) << path;
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// ------------------------------------------------------------ validation

// The mesh line every case starts from; the case's text is line 2.
constexpr char kMeshLine[] = "mesh { block { nx: 1 ny: 1 nz: 1 } }\n";

struct RuleCase {
  std::string text;     // line 2 of the scene
  std::string anchor;   // the reported position is the first occurrence of this in `text`
  std::string message;  // the message after "case.textproto:2:col: " starts with this
};

// One case per rule: the message names the field path and the rule, at the
// position of that field (or of its closest enclosing field in the text).
TEST(DynamicsValidationTest, EveryRuleNamesTheFieldAtItsPosition) {
  const RuleCase cases[] = {
      // Materials.
      {"materials { base { young_modulus: -1 } }", "young_modulus",
       "materials.base.young_modulus must be > 0 pascals and finite, or 0 for the default 100000, "
       "got -1"},
      {"materials { base { young_modulus: inf } }", "young_modulus",
       "materials.base.young_modulus must be finite, got inf"},
      {"materials { base { poisson_ratio: 0.5 } }", "poisson_ratio",
       "materials.base.poisson_ratio must be in [0, 0.5) (0 means the default 0.3"},
      {"materials { base { poisson_ratio: -0.1 } }", "poisson_ratio",
       "materials.base.poisson_ratio must be in [0, 0.5)"},
      {"materials { base { density: -1000 } }", "density",
       "materials.base.density must be > 0 kg/m^3 and finite, or 0 for the default 1000, "
       "got -1000"},
      {"materials { base { damping: -2 } }", "damping",
       "materials.base.damping must be >= 0 kg/(m^3 s) and finite (0 = no damping), got -2"},
      {"materials { regions { } regions { material { poisson_ratio: 0.7 } } }", "poisson_ratio",
       "materials.regions[1].material.poisson_ratio must be in [0, 0.5)"},
      {"materials { regions { material { density: -1 } } }", "density",
       "materials.regions[0].material.density must be > 0"},
      // Regions.
      {"materials { regions { region { box { min { y: 2 } max { y: 1 } } } } }", "y: 2",
       "materials.regions[0].region.box.min.y (2) must be <= box.max.y (1)"},
      {"materials { regions { region { box { max { z: -1 } } } } }", "box",
       "materials.regions[0].region.box.min.z (0) must be <= box.max.z (-1)"},
      {"materials { regions { region { sphere { center { x: 1 } } } } }", "sphere",
       "materials.regions[0].region.sphere.radius must be > 0 metres, got 0"},
      {"materials { regions { region { sphere { radius: -0.5 } } } }", "radius",
       "materials.regions[0].region.sphere.radius must be > 0 metres, got -0.5"},
      {"materials { regions { region { control_cells: 0 control_cells: -2 } } }",
       "control_cells: -2",
       "materials.regions[0].region.control_cells[1] must be a cell index >= 0, got -2"},
      {"materials { regions { region { sphere { center { z: nan } radius: 1 } } } }", "z: nan",
       "materials.regions[0].region.sphere.center.z must be finite, got nan"},
      // Constraints.
      {"constraints { fixed { } fixed { box { min { z: 0.5 } max { z: 0.25 } } } }", "z: 0.5",
       "constraints.fixed[1].box.min.z (0.5) must be <= box.max.z (0.25)"},
      {"constraints { fixed { sphere { radius: -1 } } }", "radius",
       "constraints.fixed[0].sphere.radius must be > 0 metres, got -1"},
      {"constraints { fixed { control_cells: -1 } }", "control_cells",
       "constraints.fixed[0].control_cells[0] must be a cell index >= 0, got -1"},
      {"constraints { springs { region { control_cells: 0 } stiffness: -1e6 } }", "stiffness",
       "constraints.springs[0].stiffness must be >= 0 N/m, got -1e+06"},
      {"constraints { springs { region { box { min { x: 1 } } } stiffness: 10 } }", "x: 1",
       "constraints.springs[0].region.box.min.x (1) must be <= box.max.x (0)"},
      {"constraints { springs { stiffness: inf } }", "stiffness",
       "constraints.springs[0].stiffness must be finite, got inf"},
      // Loads and the initial state: finite numbers only.
      {"loads { point_forces { position { x: 1 } force { y: nan } } }", "y: nan",
       "loads.point_forces[0].force.y must be finite, got nan"},
      {"loads { point_forces { } point_forces { position { x: -inf } } }", "x: -inf",
       "loads.point_forces[1].position.x must be finite, got -inf"},
      {"loads { gravity { z: -inf } }", "z: -inf", "loads.gravity.z must be finite, got -inf"},
      {"initial { angular_velocity { x: nan } }", "x: nan",
       "initial.angular_velocity.x must be finite, got nan"},
      {"initial { linear_velocity { z: inf } }", "z: inf",
       "initial.linear_velocity.z must be finite, got inf"},
      // Traced points.
      {"traced { name: \"a\" } traced { position { x: 1 } }", "traced { position",
       "traced[1].name is empty: every traced point needs a name"},
      {"traced { name: \"tip\" } traced { name: \"base\" } "
       "traced { name: \"tip\" position { x: 1 } }",
       "name: \"tip\" position",
       "traced[2].name \"tip\" is already the name of traced[0]: names must be unique"},
      {"traced { name: \"a,b\" }", "name",
       "traced[0].name \"a,b\" must not contain control characters, commas or double quotes"},
      {"traced { name: \"a\\nb\" }", "name", "traced[0].name \"a\\nb\" must not contain"},
      {"traced { name: \"q\\\"\" }", "name", "traced[0].name \"q\\\"\" must not contain"},
      {"traced { name: \"t\" position { y: nan } }", "y: nan",
       "traced[0].position.y must be finite, got nan"},
      // Solver settings.
      {"solver { time_step: -0.001 }", "time_step",
       "solver.time_step must be in (0, 1] seconds, or 0 for the default 0.001, got -0.001"},
      {"solver { time_step: 2 }", "time_step", "solver.time_step must be in (0, 1] seconds"},
      {"solver { time_step: nan }", "time_step", "solver.time_step must be finite, got nan"},
      {"solver { cg_tolerance: 1 }", "cg_tolerance",
       "solver.cg_tolerance must be in (0, 1), or 0 for the default 0.0001, got 1"},
      {"solver { cg_tolerance: -1e-4 }", "cg_tolerance", "solver.cg_tolerance must be in (0, 1)"},
      {"solver { cg_max_iterations: -1 }", "cg_max_iterations",
       "solver.cg_max_iterations must be >= 1, or 0 for the default 500, got -1"},
      {"solver { max_substeps: -5 }", "max_substeps",
       "solver.max_substeps must be >= 1, or 0 for the default 1000, got -5"},
      {"solver { stability_safety: 1.5 }", "stability_safety",
       "solver.stability_safety must be in (0, 1], or 0 for the default 0.9, got 1.5"},
      {"solver { stability_safety: -0.1 }", "stability_safety",
       "solver.stability_safety must be in (0, 1]"},
      // Enums: text format (proto3) accepts any number; only declared ones pass.
      {"solver { model: 7 }", "model",
       "solver.model has the unknown value 7; Model is one of MODEL_DEFAULT (0), LOCAL_FRAME (1), "
       "COROTATIONAL (2)"},
      {"solver { integrator: -1 }", "integrator",
       "solver.integrator has the unknown value -1; Integrator is one of INTEGRATOR_DEFAULT (0), "
       "CENTRAL_DIFFERENCE (1), BACKWARD_EULER (2), AUTO (3)"},
  };
  for (const RuleCase& c : cases) {
    const size_t at = c.text.find(c.anchor);
    ASSERT_NE(at, std::string::npos) << c.anchor << " not in " << c.text;
    const std::string where = absl::StrCat("case.textproto:2:", at + 1, ": ");
    EXPECT_THAT(ParseScene(kMeshLine + c.text + "\n", "case.textproto"),
                StatusIs(absl::StatusCode::kInvalidArgument, StartsWith(where + c.message)))
        << c.text;
  }
}

// The same rules over several lines, positions counted by hand.
TEST(DynamicsValidationTest, PositionsInAMultiLineScene) {
  const std::string text =
      "name: \"beam\"\n"                                       // 1
      "mesh { beam { length: 1 width: 0.1 height: 0.1\n"       // 2
      "              cells_along: 10 cells_across: 1 } }\n"    // 3
      "materials {\n"                                          // 4
      "  base { young_modulus: 1e6 }\n"                        // 5
      "  regions {\n"                                          // 6
      "    region { sphere { center { x: 1 } radius: 0.1 } }\n"  // 7
      "    material { poisson_ratio: 0.55 }\n"                 // 8
      "  }\n"                                                  // 9
      "}\n";                                                   // 10
  EXPECT_THAT(ParseScene(text, "beam.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("beam.textproto:8:16: "
                                  "materials.regions[0].material.poisson_ratio must be in "
                                  "[0, 0.5)")));

  const std::string traced =
      "mesh { block { nx: 1 ny: 1 nz: 1 } }\n"  // 1
      "traced {\n"                              // 2
      "  name: \"tip\"\n"                       // 3
      "}\n"                                     // 4
      "traced {\n"                              // 5
      "  position { x: 1 }\n"                   // 6
      "  name: \"tip\"\n"                       // 7
      "}\n";                                    // 8
  EXPECT_THAT(ParseScene(traced, "t.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("t.textproto:7:3: traced[1].name \"tip\" is already the name of "
                                  "traced[0]")));

  const std::string solver =
      "mesh { block { nx: 1 ny: 1 nz: 1 } }\n"  // 1
      "solver {\n"                              // 2
      "  integrator: BACKWARD_EULER\n"          // 3
      "  time_step: 5\n"                        // 4
      "}\n";                                    // 5
  EXPECT_THAT(ParseScene(solver, "s.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("s.textproto:4:3: solver.time_step must be in (0, 1] seconds")));
}

TEST(DynamicsValidationTest, ParserRejectsUnknownEnumNamesAndTwoShapes) {
  EXPECT_THAT(ParseScene(absl::StrCat(kMeshLine, "solver { model: FEM }\n"), "e.textproto"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(StartsWith("e.textproto:2:"),
                             HasSubstr("Unknown enumeration value of \"FEM\""))));
  EXPECT_THAT(
      ParseScene(absl::StrCat(kMeshLine,
                              "constraints { fixed { box { } sphere { radius: 1 } } }\n"),
                 "o.textproto"),
      StatusIs(absl::StatusCode::kInvalidArgument, StartsWith("o.textproto:2:")));
}

TEST(DynamicsValidationTest, AcceptsTheLimitsOfEveryRange) {
  const std::string text = absl::StrCat(
      kMeshLine,
      "materials {\n"
      "  base { young_modulus: 1e12 poisson_ratio: 0.499 density: 1e-6 damping: 0 }\n"
      "  regions { }\n"  // an empty region paints nothing
      "  regions { region { box { min { x: 1 y: 1 z: 1 } max { x: 1 y: 1 z: 1 } } } }\n"
      "  regions { region { control_cells: 0 sphere { radius: 1e-9 } } material { } }\n"
      "}\n"
      "initial { linear_velocity { x: -3 } angular_velocity { z: 100 } }\n"
      "loads { point_forces { } gravity { z: -9.81 } }\n"
      "constraints { fixed { } springs { stiffness: 0 } }\n"
      "traced { name: \"tip point (m)\" } traced { name: \"Tip\" }\n"
      "solver { model: COROTATIONAL integrator: AUTO time_step: 1 cg_tolerance: 0.999\n"
      "         cg_max_iterations: 1 max_substeps: 1 stability_safety: 1\n"
      "         snap_forces_to_quadrature: true }\n");
  EXPECT_OK(ParseScene(text, "limits.textproto"));
  // Zeros everywhere mean defaults: a scene without dynamics is valid.
  EXPECT_OK(ParseScene(absl::StrCat(kMeshLine, "materials { base { } } solver { }\n"), "zeros"));
}

// A scene built in code is checked the same way (no positions there).
TEST(DynamicsValidationTest, ValidateSceneOnAMessage) {
  Scene scene;
  scene.mutable_mesh()->mutable_block()->set_nx(1);
  scene.mutable_mesh()->mutable_block()->set_ny(1);
  scene.mutable_mesh()->mutable_block()->set_nz(1);
  EXPECT_OK(ValidateScene(scene));
  scene.mutable_solver()->set_model(static_cast<SolverSettings::Model>(42));
  EXPECT_THAT(ValidateScene(scene), StatusIs(absl::StatusCode::kInvalidArgument,
                                             StartsWith("solver.model has the unknown value 42")));
  scene.mutable_solver()->clear_model();
  scene.mutable_materials()->add_regions()->mutable_material()->set_damping(-1);
  EXPECT_THAT(ValidateScene(scene),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("materials.regions[0].material.damping must be >= 0")));
  // ControlMeshInput validates too, naming the scene.
  scene.set_name("s");
  EXPECT_THAT(ControlMeshInput(scene, ""),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("scene s: materials.regions[0].material.damping")));
}

TEST(DynamicsValidationTest, ValidateMaterialNamesItsField) {
  Material m;
  EXPECT_OK(ValidateMaterial(m));
  m.set_poisson_ratio(0.5);
  EXPECT_THAT(ValidateMaterial(m, "paint.material"),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       StartsWith("paint.material.poisson_ratio must be in [0, 0.5)")));
  m.set_poisson_ratio(std::numeric_limits<double>::quiet_NaN());
  EXPECT_THAT(ValidateMaterial(m), StatusIs(absl::StatusCode::kInvalidArgument,
                                            StartsWith("material.poisson_ratio must be in")));
  m.set_poisson_ratio(0.25);
  m.set_young_modulus(std::numeric_limits<double>::infinity());
  EXPECT_THAT(ValidateMaterial(m), StatusIs(absl::StatusCode::kInvalidArgument,
                                            StartsWith("material.young_modulus must be > 0")));
}

// Every double field of the schema, wherever it sits, is rejected when NaN
// or infinite, naming its path at its position; every enum field rejects an
// undeclared number. Walks the descriptors, so new fields are covered
// without touching this test.
class EveryFieldTest : public ::testing::Test {
 protected:
  // Visits every scalar field reachable from `descriptor` (a repeated
  // field as its element [0]); `path` is the list of fields to it.
  static void Walk(const Descriptor* descriptor, std::vector<const FieldDescriptor*>& path,
                   const std::function<void(const std::vector<const FieldDescriptor*>&)>& visit) {
    ASSERT_LT(path.size(), 12u) << "recursive message?";
    for (int i = 0; i < descriptor->field_count(); ++i) {
      const FieldDescriptor* field = descriptor->field(i);
      path.push_back(field);
      if (field->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
        Walk(field->message_type(), path, visit);
      } else {
        visit(path);
      }
      path.pop_back();
    }
  }

  // The message holding the last field of `path` inside `scene` (created
  // on the way; repeated fields get one element), and the path's text.
  static Message* Holder(Scene& scene, const std::vector<const FieldDescriptor*>& path,
                         std::string* name) {
    Message* message = &scene;
    for (size_t i = 0; i < path.size(); ++i) {
      const FieldDescriptor* field = path[i];
      absl::StrAppend(name, i == 0 ? "" : ".", field->name(), field->is_repeated() ? "[0]" : "");
      if (i + 1 == path.size()) break;
      const Reflection* r = message->GetReflection();
      message = field->is_repeated() ? r->AddMessage(message, field)
                                     : r->MutableMessage(message, field);
    }
    return message;
  }

  static Scene ValidBase() {
    Scene scene;
    EXPECT_TRUE(TextFormat::ParseFromString(
        "name: \"base\" mesh { block { nx: 1 ny: 1 nz: 1 } }", &scene));
    EXPECT_OK(ValidateScene(scene));
    return scene;
  }

  // The error must read "every:LINE:COL: <path> ..." with the path's field
  // at LINE:COL in `text`.
  static void ExpectPositioned(const Scene& scene, const std::string& name,
                               const std::string& rule) {
    std::string text;
    ASSERT_TRUE(TextFormat::PrintToString(scene, &text));
    absl::StatusOr<Scene> parsed = ParseScene(text, "every");
    ASSERT_FALSE(parsed.ok()) << name << " accepted:\n" << text;
    const std::string message(parsed.status().message());
    std::smatch m;
    ASSERT_TRUE(std::regex_search(message, m, std::regex("^every:([0-9]+):([0-9]+): ")))
        << message;
    EXPECT_EQ(message.substr(m.length(0)), absl::StrCat(name, " ", rule)) << text;
    // The position points at the field's own name in the printed text.
    const int line = std::stoi(m[1]), col = std::stoi(m[2]);
    std::vector<std::string> lines;
    for (size_t begin = 0, end; begin < text.size(); begin = end + 1) {
      end = text.find('\n', begin);
      if (end == std::string::npos) end = text.size();
      lines.push_back(text.substr(begin, end - begin));
    }
    ASSERT_LE(line, static_cast<int>(lines.size())) << message;
    const std::string leaf = name.substr(name.find_last_of('.') + 1);
    const std::string leaf_name = leaf.substr(0, leaf.find('['));
    EXPECT_EQ(lines[line - 1].substr(col - 1, leaf_name.size()), leaf_name)
        << message << "\n" << text;
  }
};

TEST_F(EveryFieldTest, NonFiniteDoublesAreRejectedNamingTheField) {
  int visited = 0;
  std::vector<const FieldDescriptor*> path;
  Walk(Scene::descriptor(), path, [&](const std::vector<const FieldDescriptor*>& fields) {
    const FieldDescriptor* leaf = fields.back();
    if (leaf->cpp_type() != FieldDescriptor::CPPTYPE_DOUBLE) return;
    for (const double bad : {std::numeric_limits<double>::quiet_NaN(),
                             std::numeric_limits<double>::infinity(),
                             -std::numeric_limits<double>::infinity()}) {
      Scene scene = ValidBase();
      std::string name;
      Message* holder = Holder(scene, fields, &name);
      const Reflection* r = holder->GetReflection();
      if (leaf->is_repeated()) {
        r->AddDouble(holder, leaf, bad);
      } else {
        r->SetDouble(holder, leaf, bad);
      }
      SCOPED_TRACE(name);
      const std::string rule = absl::StrCat("must be finite, got ", bad);
      EXPECT_THAT(ValidateScene(scene),
                  StatusIs(absl::StatusCode::kInvalidArgument, absl::StrCat(name, " ", rule)));
      ExpectPositioned(scene, name, rule);
    }
    ++visited;
  });
  // Vec3 x/y/z in every place, the generators, the materials, the solver...
  EXPECT_GE(visited, 60);
}

TEST_F(EveryFieldTest, UndeclaredEnumNumbersAreRejectedNamingTheField) {
  int visited = 0;
  std::vector<const FieldDescriptor*> path;
  Walk(Scene::descriptor(), path, [&](const std::vector<const FieldDescriptor*>& fields) {
    const FieldDescriptor* leaf = fields.back();
    if (leaf->cpp_type() != FieldDescriptor::CPPTYPE_ENUM) return;
    Scene scene = ValidBase();
    std::string name;
    Message* holder = Holder(scene, fields, &name);
    const Reflection* r = holder->GetReflection();
    if (leaf->is_repeated()) {
      r->AddEnumValue(holder, leaf, 99);
    } else {
      r->SetEnumValue(holder, leaf, 99);
    }
    SCOPED_TRACE(name);
    EXPECT_THAT(ValidateScene(scene),
                StatusIs(absl::StatusCode::kInvalidArgument,
                         StartsWith(absl::StrCat(name, " has the unknown value 99; "))));
    std::string rule;
    rule = std::string(ValidateScene(scene).message()).substr(name.size() + 1);
    ExpectPositioned(scene, name, rule);
    ++visited;
  });
  // solver.model, .integrator, .element_products, .mass, .corotation,
  // .explicit_solve and materials.base.preset,
  // materials.regions.material.preset.
  EXPECT_EQ(visited, 8);
}

// ------------------------------------------------------------- defaults

TEST(DefaultsTest, EmptySolverSettingsResolveToTheDocumentedDefaults) {
  const SolverSettings s = ResolvedSolverSettings(Scene());
  EXPECT_EQ(s.model(), SolverSettings::LOCAL_FRAME);
  EXPECT_EQ(s.integrator(), SolverSettings::CENTRAL_DIFFERENCE);
  EXPECT_EQ(s.time_step(), 1e-3);
  EXPECT_EQ(s.cg_tolerance(), 1e-4);
  EXPECT_EQ(s.cg_max_iterations(), 500);
  EXPECT_EQ(s.max_substeps(), 1000);
  EXPECT_EQ(s.stability_safety(), 0.9);
  EXPECT_FALSE(s.snap_forces_to_quadrature());
  EXPECT_EQ(s.element_products(), SolverSettings::FLOAT);
  EXPECT_EQ(s.mass(), SolverSettings::CONSISTENT);
  EXPECT_EQ(s.corotation(), SolverSettings::ELEMENT);
  EXPECT_EQ(s.explicit_solve(), SolverSettings::FACTORED);
  // A resolved scene is still valid, and resolving is idempotent.
  Scene scene;
  scene.mutable_mesh()->set_file("x.vtk");
  *scene.mutable_solver() = s;
  EXPECT_OK(ValidateScene(scene));
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(ResolvedSolverSettings(s), s));
}

TEST(DefaultsTest, GivenSolverSettingsAreKept) {
  Scene scene;
  SolverSettings* given = scene.mutable_solver();
  given->set_model(SolverSettings::COROTATIONAL);
  given->set_integrator(SolverSettings::AUTO);  // the solver decides: not resolved here
  given->set_time_step(2.5e-4);
  given->set_cg_tolerance(1e-8);
  given->set_cg_max_iterations(7);
  given->set_max_substeps(1);
  given->set_stability_safety(0.5);
  given->set_snap_forces_to_quadrature(true);
  given->set_element_products(SolverSettings::DOUBLE);
  given->set_mass(SolverSettings::LUMPED);
  given->set_corotation(SolverSettings::CONTROL_CELL);
  given->set_explicit_solve(SolverSettings::CG);
  EXPECT_TRUE(
      google::protobuf::util::MessageDifferencer::Equals(ResolvedSolverSettings(scene), *given));

  SolverSettings partial;
  partial.set_integrator(SolverSettings::BACKWARD_EULER);
  partial.set_max_substeps(1);
  const SolverSettings s = ResolvedSolverSettings(partial);
  EXPECT_EQ(s.model(), SolverSettings::LOCAL_FRAME);
  EXPECT_EQ(s.integrator(), SolverSettings::BACKWARD_EULER);
  EXPECT_EQ(s.max_substeps(), 1);
  EXPECT_EQ(s.time_step(), kDefaultTimeStep);
  EXPECT_EQ(s.cg_max_iterations(), kDefaultCgMaxIterations);
}

TEST(DefaultsTest, MaterialZerosResolveToTheDocumentedDefaults) {
  const Material m = ResolvedMaterial(Material());
  EXPECT_EQ(m.young_modulus(), 1e5);
  EXPECT_EQ(m.poisson_ratio(), 0.3);
  EXPECT_EQ(m.density(), 1000);
  EXPECT_EQ(m.damping(), 0);  // no damping matrix

  Material given;
  given.set_young_modulus(2e11);
  given.set_poisson_ratio(0.29);
  given.set_density(7850);
  given.set_damping(3);
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(ResolvedMaterial(given), given));

  // A region's material resolves on its own: zeros are the defaults, not
  // the base's values.
  Material partial;
  partial.set_density(500);
  const Material r = ResolvedMaterial(partial);
  EXPECT_EQ(r.density(), 500);
  EXPECT_EQ(r.young_modulus(), kDefaultYoungModulus);
  EXPECT_EQ(r.poisson_ratio(), kDefaultPoissonRatio);
  EXPECT_OK(ValidateMaterial(r));
}

// ------------------------------------------------------ example scenes

bool Inside(const Region& region, const Eigen::RowVector3d& p) {
  if (region.has_box()) {
    const Box& b = region.box();
    return p.x() >= b.min().x() && p.x() <= b.max().x() && p.y() >= b.min().y() &&
           p.y() <= b.max().y() && p.z() >= b.min().z() && p.z() <= b.max().z();
  }
  if (region.has_sphere()) {
    const Sphere& s = region.sphere();
    return (p - Eigen::RowVector3d(s.center().x(), s.center().y(), s.center().z())).norm() <=
           s.radius();
  }
  return false;
}

// True when `p` lies in the axis-aligned bounds of some control cell's
// vertices (a loose "inside the solid" for the scenes' points).
bool InSomeCellBounds(const mesh::MeshInput& input, const Vec3& v) {
  const Eigen::RowVector3d p(v.x(), v.y(), v.z());
  for (const auto& cell : input.cells) {
    Eigen::RowVector3d lo = Eigen::RowVector3d::Constant(1e300), hi = -lo;
    for (const auto& face : cell) {
      for (const int32_t i : face) {
        lo = lo.cwiseMin(input.vertices.row(i));
        hi = hi.cwiseMax(input.vertices.row(i));
      }
    }
    if ((p.array() >= lo.array() - 1e-12).all() && (p.array() <= hi.array() + 1e-12).all()) {
      return true;
    }
  }
  return false;
}

// Every example scene sets its material and solver explicitly, and its
// fixed regions hold the control points they are meant to.
TEST(ExampleScenesTest, EverySceneHasDynamicsThatFitItsMesh) {
  // Control points inside constraints.fixed (none: a free solid).
  const std::map<std::string, int> fixed_points = {
      {"block3", 16}, {"block4", 0},  {"chair", 0}, {"bridge", 36},
      {"nozzle", 22}, {"torus", 0},   {"mixed", 4},  {"beam", 4},
      {"clay", 25},
  };
  for (const std::string& name : BuiltinSceneNames()) {
    SCOPED_TRACE(name);
    absl::StatusOr<Scene> scene = BuiltinScene(name);
    ASSERT_OK(scene);
    EXPECT_GT(scene->materials().base().young_modulus(), 0) << "set the material explicitly";
    EXPECT_GT(scene->materials().base().density(), 0);
    EXPECT_GT(scene->solver().time_step(), 0) << "set the time step explicitly";
    EXPECT_NE(scene->solver().model(), SolverSettings::MODEL_DEFAULT);
    EXPECT_NE(scene->solver().integrator(), SolverSettings::INTEGRATOR_DEFAULT);
    EXPECT_FALSE(scene->traced().empty()) << "trace at least one point";
    EXPECT_THAT(scene->description(), HasSubstr("Exercises"));

    absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, BuiltinSceneDir());
    ASSERT_OK(input);
    int fixed = 0;
    for (int64_t v = 0; v < input->vertices.rows(); ++v) {
      for (const Region& region : scene->constraints().fixed()) {
        if (Inside(region, input->vertices.row(v))) {
          ++fixed;
          break;
        }
      }
    }
    ASSERT_TRUE(fixed_points.contains(name)) << "add " << name << " to fixed_points";
    EXPECT_EQ(fixed, fixed_points.at(name)) << "control points in constraints.fixed";
    for (const PenaltySpring& spring : scene->constraints().springs()) {
      int held = 0;
      for (int64_t v = 0; v < input->vertices.rows(); ++v) {
        held += Inside(spring.region(), input->vertices.row(v));
      }
      EXPECT_GT(held, 0) << "a penalty spring region holds no control point";
    }
    for (const TracedPoint& t : scene->traced()) {
      EXPECT_TRUE(InSomeCellBounds(*input, t.position())) << "traced " << t.name();
    }
    for (const PointForce& f : scene->loads().point_forces()) {
      EXPECT_TRUE(InSomeCellBounds(*input, f.position())) << "point force";
    }
    for (const MaterialRegion& r : scene->materials().regions()) {
      for (const int32_t c : r.region().control_cells()) {
        EXPECT_LT(c, static_cast<int32_t>(input->cells.size())) << "materials region cell";
      }
    }
  }
}

TEST(ExampleScenesTest, BeamIsAClampedCantileverWithATipLoad) {
  absl::StatusOr<Scene> beam = BuiltinScene("beam");
  ASSERT_OK(beam);
  EXPECT_EQ(beam->materials().base().young_modulus(), 1e6);
  EXPECT_EQ(beam->solver().time_step(), 1e-3);
  ASSERT_EQ(beam->traced_size(), 1);
  EXPECT_EQ(beam->traced(0).name(), "tip");
  EXPECT_EQ(beam->traced(0).position().x(), 1.0);
  ASSERT_EQ(beam->loads().point_forces_size(), 1);
  EXPECT_EQ(beam->loads().point_forces(0).position().x(), 1.0);
  EXPECT_LT(beam->loads().point_forces(0).force().z(), 0);
  EXPECT_FALSE(beam->loads().has_gravity()) << "the accuracy test compares with a tip load alone";
  ASSERT_EQ(beam->constraints().fixed_size(), 1);
  EXPECT_TRUE(beam->constraints().fixed(0).has_box());
}

TEST(ExampleScenesTest, TorusSpinsAndMixedIsPushed) {
  absl::StatusOr<Scene> torus = BuiltinScene("torus");
  ASSERT_OK(torus);
  EXPECT_NE(torus->initial().angular_velocity().z(), 0);
  EXPECT_EQ(torus->constraints().fixed_size(), 0);
  absl::StatusOr<Scene> mixed = BuiltinScene("mixed");
  ASSERT_OK(mixed);
  EXPECT_EQ(mixed->loads().point_forces_size(), 1);
  for (const std::string name : {"chair", "bridge", "block4"}) {
    absl::StatusOr<Scene> scene = BuiltinScene(name);
    ASSERT_OK(scene);
    EXPECT_LT(scene->loads().gravity().z(), 0) << name;
  }
}

// ------------------------------------------------------------ docs

std::vector<std::string> TextprotoBlocks(const std::string& doc) {
  std::vector<std::string> blocks;
  const std::string open = "```textproto\n";
  for (size_t begin = doc.find(open); begin != std::string::npos; begin = doc.find(open, begin)) {
    begin += open.size();
    const size_t end = doc.find("```", begin);
    if (end == std::string::npos) break;
    blocks.push_back(doc.substr(begin, end - begin));
    begin = end + 3;
  }
  return blocks;
}

TEST(SceneDocDynamicsTest, EveryExampleLoadsAndTheCantileverHasItAll) {
  const std::string doc = ReadText(SourceDir() / "docs" / "scene.md");
  const std::vector<std::string> blocks = TextprotoBlocks(doc);
  ASSERT_GE(blocks.size(), 2u) << "docs/scene.md: the geometry example and the dynamics example";
  bool found_cantilever = false;
  for (size_t i = 0; i < blocks.size(); ++i) {
    absl::StatusOr<Scene> scene = ParseScene(blocks[i], absl::StrCat("docs/scene.md block ", i));
    ASSERT_OK(scene);
    absl::StatusOr<mesh::MeshInput> input = ControlMeshInput(*scene, "");
    ASSERT_OK(input);
    ASSERT_OK(mesh::CellComplex::FromInput(*input));
    if (!scene->mesh().has_beam()) continue;
    found_cantilever = true;
    EXPECT_GT(scene->materials().base().young_modulus(), 0);
    EXPECT_LT(scene->loads().gravity().z(), 0);
    EXPECT_EQ(scene->loads().point_forces_size(), 1);
    ASSERT_EQ(scene->constraints().fixed_size(), 1);
    int fixed = 0;
    for (int64_t v = 0; v < input->vertices.rows(); ++v) {
      if (Inside(scene->constraints().fixed(0), input->vertices.row(v))) {
        EXPECT_EQ(input->vertices(v, 0), 0.0) << "only the end x = 0 is fixed";
        ++fixed;
      }
    }
    EXPECT_GT(fixed, 0);
    ASSERT_EQ(scene->traced_size(), 1);
    EXPECT_EQ(scene->traced(0).position().x(), scene->mesh().beam().length());
    EXPECT_GT(scene->solver().time_step(), 0);
  }
  EXPECT_TRUE(found_cantilever) << "docs/scene.md needs the cantilever example";
}

// Every field of every message reachable from Scene appears in the docs as
// `name`, and every message type has a heading or table mention.
TEST(SceneDocDynamicsTest, EveryFieldIsDocumented) {
  const std::string doc = ReadText(SourceDir() / "docs" / "scene.md");
  std::vector<std::string> missing;
  std::set<const Descriptor*> seen;
  std::vector<const Descriptor*> todo = {Scene::descriptor()};
  while (!todo.empty()) {
    const Descriptor* d = todo.back();
    todo.pop_back();
    if (!seen.insert(d).second) continue;
    if (doc.find(d->name()) == std::string::npos) missing.push_back(d->full_name());
    for (int i = 0; i < d->field_count(); ++i) {
      const FieldDescriptor* f = d->field(i);
      if (doc.find(absl::StrCat("`", f->name(), "`")) == std::string::npos) {
        missing.push_back(f->full_name());
      }
      if (f->message_type() != nullptr) todo.push_back(f->message_type());
      if (f->enum_type() != nullptr) {
        for (int v = 0; v < f->enum_type()->value_count(); ++v) {
          if (doc.find(absl::StrCat("`", f->enum_type()->value(v)->name(), "`")) ==
              std::string::npos) {
            missing.push_back(f->enum_type()->value(v)->full_name());
          }
        }
      }
    }
  }
  EXPECT_THAT(missing, ::testing::IsEmpty()) << "not in docs/scene.md (as `name`)";
}

}  // namespace
}  // namespace dynsolid::scene
