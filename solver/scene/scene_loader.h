// Scene loading: text-format scene files (proto/dynsolid/scene.proto), the
// built-in scenes, and the level-0 control mesh a scene names.
//
// A scene file is a dynsolid.Scene in protobuf text format (docs/scene.md).
// Every error is an absl::Status whose message says where: parse errors and
// invalid fields read "origin:line:col: message" (1-based line and column;
// for an invalid field, the position of that field, or of its closest
// enclosing field present in the text), e.g.
//   scenes/nozzle.textproto:9:5: mesh.tube.inner_radius (2) must be less
//   than tube.outer_radius (1)
// Field errors name the field by its path from the Scene message.
//
// Nothing here keeps state: every call parses or builds afresh.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include <google/protobuf/message.h>
#include "dynsolid/scene.pb.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::scene {

// Checks every field that can be checked without reading a mesh file or
// building the mesh. InvalidArgument, message starting with the field path
// ("subdivision.levels must be in 0..4, got 7"); the first failure found,
// in this order:
//  - a mesh source is set;
//  - every double in the scene is finite and every enum holds a known value
//    (proto3 text format and the wire both accept unknown enum numbers);
//  - mesh: generator parameters, mesh.scale >= 0, mesh.refine_cells >= 0;
//  - subdivision.levels in 0..4; sharp.crease_angle_degrees in [0, 180];
//    sharp.edges indices >= 0 and distinct;
//  - materials (base and every region's material): ValidateMaterial;
//  - regions (materials.regions[i].region, constraints.fixed[i],
//    constraints.springs[i].region): box.min <= box.max componentwise,
//    sphere.radius > 0, control_cells >= 0 (their upper bound is checked by
//    the solver against the mesh after refinement);
//  - constraints.springs[i].stiffness >= 0;
//  - loads.pressures[i]: ValidatePressure;
//  - traced[i].name non-empty, unique, and free of control characters,
//    commas and double quotes (it is a column name of trace.csv);
//  - solver: time_step in [0, 1] s, cg_tolerance in [0, 1),
//    cg_max_iterations >= 0, max_substeps >= 0, stability_safety in [0, 1]
//    (0 in each means the default: see ResolvedSolverSettings).
// Positions (point forces, traced points) are not checked against the
// solid here: the solver does that when it builds.
absl::Status ValidateScene(const Scene& scene);

// A material's own rules: young_modulus >= 0, poisson_ratio in [0, 0.5),
// density >= 0, damping >= 0, all finite (0 = the default, see
// ResolvedMaterial). `field` names the material in messages
// ("materials.base": "materials.base.poisson_ratio must be in [0, 0.5) ...").
absl::Status ValidateMaterial(const Material& material, std::string_view field = "material");

// The rules of one concept, shared by ValidateScene and the solid's runtime
// commands (solid.h), so each is written once. `field` names the value in
// messages ("loads.pressures[2]", "pressure"); every message starts with
// the path of the field at fault, e.g.
//   "pressure.region.sphere.radius must be > 0 metres, got -1".

// Every double (and float) in `message` and its sub-messages is finite and
// every enum holds a declared value ("point_force.force.x must be finite,
// got nan").
absl::Status ValidateValues(const google::protobuf::Message& message, std::string_view field);

// box.min <= box.max componentwise, sphere.radius > 0, control_cells >= 0
// (their upper bound needs the mesh: the solver checks it). An empty region
// (no shape, no cells) is allowed here; see ValidateNonEmptyRegion.
absl::Status ValidateRegion(const Region& region, std::string_view field);
// ValidateRegion, and the region has a shape or control cells.
absl::Status ValidateNonEmptyRegion(const Region& region, std::string_view field);

// Finite position and force (whether the position lies inside the solid is
// the solver's check).
absl::Status ValidatePointForce(const PointForce& force, std::string_view field);

// Finite values, a non-empty valid region, pascals != 0.
absl::Status ValidatePressure(const Pressure& pressure, std::string_view field);

// Finite values, a non-empty valid region, a valid material
// (ValidateMaterial) that sets at least one field, strength in (0, 1].
absl::Status ValidateMaterialPaint(const MaterialPaint& paint, std::string_view field);

// ---- Defaults (proto/dynsolid/scene.proto): a field left at 0 means these.

inline constexpr double kDefaultYoungModulus = 1e5;    // Pa
inline constexpr double kDefaultPoissonRatio = 0.3;
inline constexpr double kDefaultDensity = 1000.0;      // kg/m^3
inline constexpr double kDefaultDamping = 0.0;         // kg/(m^3 s): no damping
inline constexpr double kDefaultFlowRate = 50.0;       // 1/s (a material that yields)
inline constexpr double kDefaultTimeStep = 1e-3;       // s
inline constexpr double kDefaultCgTolerance = 1e-4;    // relative residual
inline constexpr int32_t kDefaultCgMaxIterations = 500;
inline constexpr int32_t kDefaultMaxSubsteps = 1000;
inline constexpr double kDefaultStabilitySafety = 0.9;

// `material` with every zero field replaced by its default: young_modulus
// 1e5, poisson_ratio 0.3, density 1000 (damping stays 0: no damping). A
// material region's material resolves on its own: a zero field there means
// the default above, not the value of materials.base.
Material ResolvedMaterial(const Material& material);
// The preset's values (scene.proto Material.Preset) in the fields
// `material` leaves at zero; the preset itself cleared. A paint's target
// goes through this before it is painted.
Material WithPreset(const Material& material);

// `settings` with every zero field replaced by its default: model
// LOCAL_FRAME, integrator CENTRAL_DIFFERENCE (AUTO stays AUTO), time_step
// 1e-3, cg_tolerance 1e-4, cg_max_iterations 500, max_substeps 1000,
// stability_safety 0.9; snap_forces_to_quadrature as given.
SolverSettings ResolvedSolverSettings(const SolverSettings& settings);
// The same for scene.solver().
SolverSettings ResolvedSolverSettings(const Scene& scene);

// Parses `text` (protobuf text format) and validates it (ValidateScene).
// `origin` names the text in messages ("scenes/chair.textproto",
// "builtin:chair"). Errors: InvalidArgument "origin:line:col: message".
absl::StatusOr<Scene> ParseScene(std::string_view text, std::string_view origin);

// The stiffness model a scene's solver settings name, as reports and
// session stats spell it: "local_frame", "corotational" (a frame per
// element) or "corotational_cells" (a frame per control cell).
std::string ModelName(const SolverSettings& settings);

// Reads and parses a scene file. NotFound when `path` does not exist.
absl::StatusOr<Scene> LoadSceneFile(const std::string& path);

// Names of the compiled-in scenes, in a fixed order: block3 (the default
// scene), block4, chair, bridge, nozzle, torus, mixed, beam.
std::vector<std::string> BuiltinSceneNames();

// The compiled-in scene `name`: the text of scenes/<name>.textproto as it
// was at build time (so the two never differ). NotFound for an unknown name;
// the message lists the known ones.
absl::StatusOr<Scene> BuiltinScene(std::string_view name);

// The text of that scene (for tools that print or export it).
absl::StatusOr<std::string_view> BuiltinSceneText(std::string_view name);

// The folder that relative mesh files of built-in scenes resolve against:
// the source tree's scenes/ folder, fixed at build time (only "mixed" reads
// a file).
std::string BuiltinSceneDir();

// A scene together with the folder its relative mesh paths resolve against.
struct LoadedScene {
  Scene scene;
  std::string base_dir;  // "" means the working directory
  std::string origin;    // "builtin:block3", "scenes/chair.textproto", "part.msh"
};

// Loads what a user names on a command line:
//  - a path ending in .textproto (or .txtpb, .pbtxt): a scene file;
//  - a path ending in .msh or .vtk: that mesh alone, wrapped in a default
//    scene (name = the file stem, subdivision.levels 2, no sharp features);
//  - otherwise a built-in scene name.
// NotFound when the file does not exist or the name is not a built-in
// (the message lists the built-in names).
absl::StatusOr<LoadedScene> LoadSceneOrMesh(std::string_view arg);

// The level-0 control mesh of `scene`: generated, or read from mesh.file
// (relative paths resolve against `base_dir`; "" = working directory), then
// transformed p' = scale * p + translate. Validates the scene first and
// then the indices it holds against the mesh (mesh.refine_cells below the
// number of cells, sharp.edges below the number of vertices). The result's
// `origin` names the scene and the source. Does not build the CellComplex:
// call mesh::CellComplex::FromInput on the result.
absl::StatusOr<mesh::MeshInput> ControlMeshInput(const Scene& scene, std::string_view base_dir);

}  // namespace dynsolid::scene
