#include "solver/scene/scene_loader.h"

#include "solver/contact/obstacle_contact.h"

#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/common/status_macros.h"
#include "solver/io/mesh_readers.h"
#include "solver/scene/generators.h"
#include "solver/scene/inline_mesh.h"

namespace dynsolid::scene {
namespace {

namespace fs = std::filesystem;
using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::TextFormat;

// The compiled-in scenes: {name, text of scenes/<name>.textproto}, generated
// at build time by embed_scenes.cmake.
struct EmbeddedScene {
  std::string_view name;
  std::string_view text;
};
constexpr EmbeddedScene kEmbeddedScenes[] = {
#include "solver/scene/builtin_scenes.inc"
};

// Largest scene file read (a scene is a few kilobytes; this only stops a
// wrong path from reading a huge file).
constexpr uintmax_t kMaxSceneFileBytes = 64u << 20;

constexpr int kMaxLevels = 4;

// Debian's Abseil keeps its own string_view (not std::string_view): the
// public API takes std::string_view and converts for absl::StrCat.
absl::string_view A(std::string_view s) { return absl::string_view(s.data(), s.size()); }

absl::Status WithPrefix(const absl::Status& status, absl::string_view prefix) {
  if (status.ok()) return status;
  return absl::Status(status.code(), absl::StrCat(prefix, status.message()));
}

// Collects the first parse error as "origin:line:col: message", 1-based.
class FirstErrorCollector : public google::protobuf::io::ErrorCollector {
 public:
  explicit FirstErrorCollector(absl::string_view origin) : origin_(origin) {}

  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    if (!error_.empty()) return;
    error_ = absl::StrCat(origin_, ":", line + 1, ":", column + 1, ": ", message);
  }

  const std::string& error() const { return error_; }

 private:
  std::string origin_;
  std::string error_;
};

// The position of the field a validation message starts with ("mesh.tube.
// inner_radius ...", "voxels.boxes[2].x1 ..."): the deepest field of that
// path present in the text. Returns false when not even the first is.
bool FindFieldLocation(absl::string_view message, const TextFormat::ParseInfoTree& root,
                       TextFormat::ParseLocation* location) {
  size_t end = 0;
  while (end < message.size() &&
         (std::isalnum(static_cast<unsigned char>(message[end])) || message[end] == '_' ||
          message[end] == '.' || message[end] == '[' || message[end] == ']')) {
    ++end;
  }
  const TextFormat::ParseInfoTree* tree = &root;
  const Descriptor* descriptor = Scene::descriptor();
  bool found = false;
  absl::string_view path = message.substr(0, end);
  while (!path.empty() && tree != nullptr && descriptor != nullptr) {
    const size_t dot = path.find('.');
    absl::string_view part = path.substr(0, dot);
    path = dot == absl::string_view::npos ? absl::string_view() : path.substr(dot + 1);
    int index = -1;
    if (const size_t bracket = part.find('['); bracket != absl::string_view::npos) {
      const size_t close = part.find(']', bracket);
      if (close == absl::string_view::npos ||
          !absl::SimpleAtoi(part.substr(bracket + 1, close - bracket - 1), &index)) {
        break;
      }
      part = part.substr(0, bracket);
    }
    const FieldDescriptor* field = descriptor->FindFieldByName(std::string(part));
    if (field == nullptr) break;
    if (field->is_repeated() != (index >= 0)) break;  // the tree needs the right index kind
    const TextFormat::ParseLocation here = tree->GetLocation(field, index);
    if (here.line < 0) break;
    *location = here;
    found = true;
    if (field->cpp_type() != FieldDescriptor::CPPTYPE_MESSAGE) break;
    tree = tree->GetTreeForNested(field, index);
    descriptor = field->message_type();
  }
  return found;
}

absl::Status CheckFinite(absl::string_view field, double value) {
  if (std::isfinite(value)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(field, " must be finite, got ", value));
}

absl::StatusOr<std::string> ReadWholeFile(const std::string& path, absl::string_view what) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) {
    return absl::NotFoundError(absl::StrCat(what, " ", path, " not found"));
  }
  if (fs::is_directory(st)) {
    return absl::InvalidArgumentError(absl::StrCat(what, " ", path, " is a directory"));
  }
  const uintmax_t size = fs::file_size(path, ec);
  if (!ec && size > kMaxSceneFileBytes) {
    return absl::InvalidArgumentError(absl::StrCat(what, " ", path, " has ", size,
                                                   " bytes, more than the limit of ",
                                                   kMaxSceneFileBytes));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::InvalidArgumentError(absl::StrCat("cannot open ", what, " ", path));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return absl::InvalidArgumentError(absl::StrCat("cannot read ", what, " ", path));
  return text;
}

std::string LowerExtension(std::string_view arg) {
  return absl::AsciiStrToLower(fs::path(std::string(arg)).extension().string());
}

std::string ParentDir(std::string_view path) {
  return fs::path(std::string(path)).parent_path().string();
}

void Transform(const ControlMesh& m, Points& p) {
  const double scale = m.scale() == 0 ? 1.0 : m.scale();
  const Eigen::RowVector3d t(m.translate().x(), m.translate().y(), m.translate().z());
  if (scale != 1.0) p *= scale;
  if (!t.isZero()) p.rowwise() += t;
}

absl::Status ValidateSolverSettings(const SolverSettings& s) {
  if (!(s.time_step() >= 0 && s.time_step() <= 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.time_step must be in (0, 1] seconds, or 0 for the default ", kDefaultTimeStep,
        ", got ", s.time_step()));
  }
  if (!(s.cg_tolerance() >= 0 && s.cg_tolerance() < 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.cg_tolerance must be in (0, 1), or 0 for the default ", kDefaultCgTolerance,
        ", got ", s.cg_tolerance()));
  }
  if (s.cg_max_iterations() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.cg_max_iterations must be >= 1, or 0 for the default ", kDefaultCgMaxIterations,
        ", got ", s.cg_max_iterations()));
  }
  if (s.max_substeps() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.max_substeps must be >= 1, or 0 for the default ", kDefaultMaxSubsteps, ", got ",
        s.max_substeps()));
  }
  if (!(s.stability_safety() >= 0 && s.stability_safety() <= 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.stability_safety must be in (0, 1], or 0 for the default ",
        kDefaultStabilitySafety, ", got ", s.stability_safety()));
  }
  if (s.corotation() == SolverSettings::CONTROL_CELL) {
    if (s.model() != SolverSettings::COROTATIONAL) {
      return absl::InvalidArgumentError(
          "solver.corotation: CONTROL_CELL takes the corotational model's frames per control "
          "cell; it needs solver.model: COROTATIONAL");
    }
  }
  return absl::OkStatus();
}

// A traced point's name is a column of trace.csv.
absl::Status ValidateTraced(const Scene& scene) {
  absl::flat_hash_map<std::string, int> first_use;
  for (int i = 0; i < scene.traced_size(); ++i) {
    const std::string& name = scene.traced(i).name();
    const std::string field = absl::StrCat("traced[", i, "].name");
    if (name.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, " is empty: every traced point needs a name (its trace.csv column)"));
    }
    for (const char c : name) {
      if (std::iscntrl(static_cast<unsigned char>(c)) || c == ',' || c == '"') {
        return absl::InvalidArgumentError(absl::StrCat(
            field, " \"", absl::CEscape(name),
            "\" must not contain control characters, commas or double quotes (it is a "
            "trace.csv column name)"));
      }
    }
    if (const auto [it, inserted] = first_use.emplace(name, i); !inserted) {
      return absl::InvalidArgumentError(absl::StrCat(field, " \"", name,
                                                     "\" is already the name of traced[",
                                                     it->second, "]: names must be unique"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

Material WithPreset(const Material& material) {
  Material m = material;
  Material preset;
  switch (m.preset()) {
    case Material::RUBBER:
      preset.set_young_modulus(1e6);
      preset.set_poisson_ratio(0.45);
      preset.set_density(1100);
      preset.set_damping(3000);
      break;
    case Material::CLAY:
      preset.set_young_modulus(1e6);
      preset.set_poisson_ratio(0.4);
      preset.set_density(1800);
      preset.set_damping(9000);
      preset.set_yield_strain(0.01);
      preset.set_flow_rate(50);
      preset.set_hardening(0.1);
      break;
    case Material::WAX:
      preset.set_young_modulus(3e6);
      preset.set_poisson_ratio(0.4);
      preset.set_density(950);
      preset.set_damping(2900);
      preset.set_yield_strain(0.02);
      preset.set_flow_rate(10);
      preset.set_hardening(0.5);
      break;
    default:
      return m;
  }
  if (m.young_modulus() == 0) m.set_young_modulus(preset.young_modulus());
  if (m.poisson_ratio() == 0) m.set_poisson_ratio(preset.poisson_ratio());
  if (m.density() == 0) m.set_density(preset.density());
  if (m.damping() == 0) m.set_damping(preset.damping());
  if (m.yield_strain() == 0) m.set_yield_strain(preset.yield_strain());
  if (m.flow_rate() == 0) m.set_flow_rate(preset.flow_rate());
  if (m.hardening() == 0) m.set_hardening(preset.hardening());
  m.clear_preset();
  return m;
}

Material ResolvedMaterial(const Material& material) {
  Material m = WithPreset(material);
  if (m.yield_strain() > 0 && m.flow_rate() == 0) m.set_flow_rate(kDefaultFlowRate);
  if (m.young_modulus() == 0) m.set_young_modulus(kDefaultYoungModulus);
  if (m.poisson_ratio() == 0) m.set_poisson_ratio(kDefaultPoissonRatio);
  if (m.density() == 0) m.set_density(kDefaultDensity);
  if (m.damping() == 0) m.set_damping(kDefaultDamping);
  return m;
}

SolverSettings ResolvedSolverSettings(const SolverSettings& settings) {
  SolverSettings s = settings;
  if (s.model() == SolverSettings::MODEL_DEFAULT) s.set_model(SolverSettings::LOCAL_FRAME);
  if (s.integrator() == SolverSettings::INTEGRATOR_DEFAULT) {
    s.set_integrator(SolverSettings::CENTRAL_DIFFERENCE);
  }
  if (s.time_step() == 0) s.set_time_step(kDefaultTimeStep);
  if (s.cg_tolerance() == 0) s.set_cg_tolerance(kDefaultCgTolerance);
  if (s.cg_max_iterations() == 0) s.set_cg_max_iterations(kDefaultCgMaxIterations);
  if (s.max_substeps() == 0) s.set_max_substeps(kDefaultMaxSubsteps);
  if (s.stability_safety() == 0) s.set_stability_safety(kDefaultStabilitySafety);
  if (s.element_products() == SolverSettings::PRECISION_DEFAULT) {
    s.set_element_products(SolverSettings::FLOAT);
  }
  if (s.mass() == SolverSettings::MASS_DEFAULT) s.set_mass(SolverSettings::CONSISTENT);
  if (s.corotation() == SolverSettings::COROTATION_DEFAULT) {
    s.set_corotation(SolverSettings::ELEMENT);
  }
  if (s.explicit_solve() == SolverSettings::EXPLICIT_SOLVE_DEFAULT) {
    s.set_explicit_solve(SolverSettings::FACTORED);
  }
  return s;
}

std::string ModelName(const SolverSettings& settings) {
  const SolverSettings s = ResolvedSolverSettings(settings);
  if (s.model() != SolverSettings::COROTATIONAL) return "local_frame";
  return s.corotation() == SolverSettings::CONTROL_CELL ? "corotational_cells" : "corotational";
}

SolverSettings ResolvedSolverSettings(const Scene& scene) {
  return ResolvedSolverSettings(scene.solver());
}

namespace {
// A material that yields needs the per-control-cell corotation (plasticity
// lives in its cells: solver/material/plasticity.h).
absl::Status ValidatePlasticModel(const Scene& scene) {
  const Materials& materials = scene.materials();
  std::string field;
  if (WithPreset(materials.base()).yield_strain() > 0) field = "materials.base";
  for (int i = 0; field.empty() && i < materials.regions_size(); ++i) {
    if (WithPreset(materials.regions(i).material()).yield_strain() > 0) {
      field = absl::StrCat("materials.regions[", i, "].material");
    }
  }
  if (field.empty()) return absl::OkStatus();
  const SolverSettings s = ResolvedSolverSettings(scene.solver());
  if (s.model() != SolverSettings::COROTATIONAL) {
    return absl::InvalidArgumentError(absl::StrCat(
        field, ".yield_strain: a material that yields (clay) needs solver.model COROTATIONAL "
               "(with either solver.corotation); this scene asks for ",
        SolverSettings::Model_Name(s.model()),
        " (the paper's local-frame model measures deformation against the rest shape "
        "through frames of its own and does not carry plastic flow)"));
  }
  return absl::OkStatus();
}
}  // namespace

absl::Status ValidateScene(const Scene& scene) {
  const ControlMesh& m = scene.mesh();
  if (m.source_case() == ControlMesh::SOURCE_NOT_SET) {
    return absl::InvalidArgumentError(
        "mesh.source is not set: the scene names no control mesh; set one of mesh.file, "
        "mesh.block, mesh.beam, mesh.tube, mesh.torus, mesh.voxels, mesh.inline_mesh");
  }
  // Non-finite numbers and unknown enum values anywhere, before the rules
  // below (which then see only finite numbers and known enum values).
  RETURN_IF_ERROR(ValidateValues(scene, ""));
  switch (m.source_case()) {
    case ControlMesh::SOURCE_NOT_SET:  // handled above
      break;
    case ControlMesh::kFile:
      if (m.file().empty()) return absl::InvalidArgumentError("mesh.file is empty");
      break;
    case ControlMesh::kBlock:
      RETURN_IF_ERROR(WithPrefix(ValidateBlock(m.block()), "mesh."));
      break;
    case ControlMesh::kBeam:
      RETURN_IF_ERROR(WithPrefix(ValidateBeam(m.beam()), "mesh."));
      break;
    case ControlMesh::kTube:
      RETURN_IF_ERROR(WithPrefix(ValidateTube(m.tube()), "mesh."));
      break;
    case ControlMesh::kTorus:
      RETURN_IF_ERROR(WithPrefix(ValidateTorus(m.torus()), "mesh."));
      break;
    case ControlMesh::kVoxels:
      RETURN_IF_ERROR(WithPrefix(ValidateVoxels(m.voxels()), "mesh."));
      break;
    case ControlMesh::kInlineMesh:
      RETURN_IF_ERROR(WithPrefix(MeshFromInline(m.inline_mesh()).status(), "mesh."));
      break;
  }
  RETURN_IF_ERROR(CheckFinite("mesh.scale", m.scale()));
  if (m.scale() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh.scale must be > 0 (0 means 1), got ", m.scale()));
  }
  RETURN_IF_ERROR(CheckFinite("mesh.translate.x", m.translate().x()));
  RETURN_IF_ERROR(CheckFinite("mesh.translate.y", m.translate().y()));
  RETURN_IF_ERROR(CheckFinite("mesh.translate.z", m.translate().z()));
  for (int i = 0; i < m.refine_cells_size(); ++i) {
    if (m.refine_cells(i) < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "mesh.refine_cells[", i, "] must be a cell index >= 0, got ", m.refine_cells(i)));
    }
  }

  const int levels = scene.subdivision().levels();
  if (levels < 0 || levels > kMaxLevels) {
    return absl::InvalidArgumentError(absl::StrCat("subdivision.levels must be in 0..",
                                                   kMaxLevels, ", got ", levels));
  }

  const double angle = scene.sharp().crease_angle_degrees();
  if (!(angle >= 0 && angle <= 180)) {  // also rejects NaN
    return absl::InvalidArgumentError(absl::StrCat(
        "sharp.crease_angle_degrees must be in [0, 180] (0 = off), got ", angle));
  }
  for (int i = 0; i < scene.sharp().edges_size(); ++i) {
    const EdgeRef& e = scene.sharp().edges(i);
    const std::string name = absl::StrCat("sharp.edges[", i, "]");
    if (e.v0() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ".v0 must be a vertex index >= 0, got ", e.v0()));
    }
    if (e.v1() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ".v1 must be a vertex index >= 0, got ", e.v1()));
    }
    if (e.v0() == e.v1()) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, " joins vertex ", e.v0(), " to itself: v0 and v1 must differ"));
    }
  }

  // Dynamics.
  const Materials& materials = scene.materials();
  RETURN_IF_ERROR(ValidateMaterial(materials.base(), "materials.base"));
  for (int i = 0; i < materials.regions_size(); ++i) {
    const std::string name = absl::StrCat("materials.regions[", i, "]");
    RETURN_IF_ERROR(ValidateRegion(materials.regions(i).region(), absl::StrCat(name, ".region")));
    RETURN_IF_ERROR(
        ValidateMaterial(materials.regions(i).material(), absl::StrCat(name, ".material")));
  }
  const Constraints& constraints = scene.constraints();
  for (int i = 0; i < constraints.fixed_size(); ++i) {
    RETURN_IF_ERROR(
        ValidateRegion(constraints.fixed(i), absl::StrCat("constraints.fixed[", i, "]")));
  }
  for (int i = 0; i < constraints.springs_size(); ++i) {
    const PenaltySpring& spring = constraints.springs(i);
    const std::string name = absl::StrCat("constraints.springs[", i, "]");
    RETURN_IF_ERROR(ValidateRegion(spring.region(), absl::StrCat(name, ".region")));
    if (!(spring.stiffness() >= 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ".stiffness must be >= 0 N/m, got ", spring.stiffness()));
    }
  }
  for (int i = 0; i < scene.loads().pressures_size(); ++i) {
    RETURN_IF_ERROR(
        ValidatePressure(scene.loads().pressures(i), absl::StrCat("loads.pressures[", i, "]")));
  }
  RETURN_IF_ERROR(ValidateTraced(scene));
  RETURN_IF_ERROR(ValidateSolverSettings(scene.solver()));
  RETURN_IF_ERROR(contact::ObstacleContact::Validate(scene.environment(), "environment"));
  RETURN_IF_ERROR(ValidatePlasticModel(scene));
  return absl::OkStatus();
}

absl::StatusOr<Scene> ParseScene(std::string_view text, std::string_view origin) {
  Scene scene;
  FirstErrorCollector errors(A(origin));
  TextFormat::ParseInfoTree locations;
  TextFormat::Parser parser;
  parser.RecordErrorsTo(&errors);
  parser.WriteLocationsTo(&locations);
  if (text.size() > kMaxSceneFileBytes) {
    return absl::InvalidArgumentError(absl::StrCat(A(origin), ": the scene text has ", text.size(),
                                                   " bytes, more than the limit of ",
                                                   kMaxSceneFileBytes));
  }
  if (!parser.ParseFromString(std::string(text), &scene)) {
    return absl::InvalidArgumentError(
        errors.error().empty() ? absl::StrCat(A(origin), ": cannot parse the scene") : errors.error());
  }
  if (absl::Status status = ValidateScene(scene); !status.ok()) {
    TextFormat::ParseLocation where;
    const std::string prefix =
        FindFieldLocation(status.message(), locations, &where)
            ? absl::StrCat(A(origin), ":", where.line + 1, ":", where.column + 1, ": ")
            : absl::StrCat(A(origin), ": ");
    return WithPrefix(status, prefix);
  }
  return scene;
}

absl::StatusOr<Scene> LoadSceneFile(const std::string& path) {
  ASSIGN_OR_RETURN(const std::string text, ReadWholeFile(path, "scene file"));
  return ParseScene(text, path);
}

std::vector<std::string> BuiltinSceneNames() {
  std::vector<std::string> names;
  for (const EmbeddedScene& s : kEmbeddedScenes) names.emplace_back(s.name);
  return names;
}

absl::StatusOr<std::string_view> BuiltinSceneText(std::string_view name) {
  for (const EmbeddedScene& s : kEmbeddedScenes) {
    if (s.name == name) return s.text;
  }
  return absl::NotFoundError(absl::StrCat("no built-in scene named \"", A(name),
                                          "\"; the built-in scenes are ",
                                          absl::StrJoin(BuiltinSceneNames(), ", ")));
}

absl::StatusOr<Scene> BuiltinScene(std::string_view name) {
  ASSIGN_OR_RETURN(const std::string_view text, BuiltinSceneText(name));
  return ParseScene(text, absl::StrCat("builtin:", A(name)));
}

std::string BuiltinSceneDir() { return DYNSOLID_SCENES_DIR; }

absl::StatusOr<LoadedScene> LoadSceneOrMesh(std::string_view arg) {
  if (arg.empty()) {
    return absl::InvalidArgumentError(
        "no scene given: name a built-in scene, a .textproto scene file or a .msh/.vtk mesh");
  }
  const std::string ext = LowerExtension(arg);
  LoadedScene loaded;
  loaded.origin = std::string(arg);
  if (ext == ".textproto" || ext == ".txtpb" || ext == ".pbtxt") {
    ASSIGN_OR_RETURN(loaded.scene, LoadSceneFile(loaded.origin));
    loaded.base_dir = ParentDir(arg);
    return loaded;
  }
  if (ext == ".msh" || ext == ".vtk") {
    std::error_code ec;
    if (!fs::exists(loaded.origin, ec)) {
      return absl::NotFoundError(absl::StrCat("mesh file ", A(arg), " not found"));
    }
    const fs::path path(loaded.origin);
    loaded.scene.set_name(path.stem().string());
    loaded.scene.set_description(absl::StrCat("The mesh ", A(arg), " with default settings."));
    loaded.scene.mutable_mesh()->set_file(path.filename().string());
    loaded.scene.mutable_subdivision()->set_levels(2);
    loaded.base_dir = path.parent_path().string();
    return loaded;
  }
  if (absl::StatusOr<Scene> builtin = BuiltinScene(arg); builtin.ok()) {
    loaded.scene = *std::move(builtin);
    loaded.base_dir = BuiltinSceneDir();
    loaded.origin = absl::StrCat("builtin:", A(arg));
    return loaded;
  } else if (!absl::IsNotFound(builtin.status())) {
    return builtin.status();
  }
  return absl::NotFoundError(absl::StrCat(
      "\"", A(arg), "\" is neither a built-in scene (", absl::StrJoin(BuiltinSceneNames(), ", "),
      ") nor a path ending in .textproto, .msh or .vtk"));
}

absl::StatusOr<mesh::MeshInput> ControlMeshInput(const Scene& scene, std::string_view base_dir) {
  const std::string prefix = scene.name().empty() ? std::string("scene: ")
                                                  : absl::StrCat("scene ", scene.name(), ": ");
  RETURN_IF_ERROR(WithPrefix(ValidateScene(scene), prefix));
  const ControlMesh& m = scene.mesh();
  absl::StatusOr<mesh::MeshInput> input;
  switch (m.source_case()) {
    case ControlMesh::kFile: {
      fs::path path(m.file());
      if (path.is_relative() && !base_dir.empty()) path = fs::path(std::string(base_dir)) / path;
      input = io::ReadMeshFile(path.string());
      if (!input.ok()) return WithPrefix(input.status(), absl::StrCat(prefix, "mesh.file: "));
      if (input->origin.empty()) input->origin = path.string();
      break;
    }
    case ControlMesh::kBlock:
      input = GenerateBlock(m.block());
      break;
    case ControlMesh::kBeam:
      input = GenerateBeam(m.beam());
      break;
    case ControlMesh::kTube:
      input = GenerateTube(m.tube());
      break;
    case ControlMesh::kTorus:
      input = GenerateTorus(m.torus());
      break;
    case ControlMesh::kVoxels:
      input = GenerateVoxels(m.voxels());
      break;
    case ControlMesh::kInlineMesh:
      input = MeshFromInline(m.inline_mesh());
      break;
    case ControlMesh::SOURCE_NOT_SET:  // rejected by ValidateScene
      return absl::InternalError("mesh.source is not set");
  }
  if (!input.ok()) return WithPrefix(input.status(), absl::StrCat(prefix, "mesh."));

  const int64_t num_cells = static_cast<int64_t>(input->cells.size());
  for (int i = 0; i < m.refine_cells_size(); ++i) {
    if (m.refine_cells(i) >= num_cells) {
      return absl::InvalidArgumentError(absl::StrCat(
          prefix, "mesh.refine_cells[", i, "] (", m.refine_cells(i),
          ") must be less than the number of control cells (", num_cells, ")"));
    }
  }
  const int64_t num_vertices = input->vertices.rows();
  for (int i = 0; i < scene.sharp().edges_size(); ++i) {
    const EdgeRef& e = scene.sharp().edges(i);
    for (const auto& [field, v] : {std::pair{"v0", e.v0()}, std::pair{"v1", e.v1()}}) {
      if (v >= num_vertices) {
        return absl::InvalidArgumentError(absl::StrCat(
            prefix, "sharp.edges[", i, "].", field, " (", v,
            ") must be less than the number of control vertices (", num_vertices, ")"));
      }
    }
  }

  Transform(m, input->vertices);
  if (!scene.name().empty()) input->origin = absl::StrCat("scene ", scene.name(), ", ", input->origin);
  return input;
}

}  // namespace dynsolid::scene
