// From a CreateSession request to a built solid: which scene, checked for
// what a network client may ask (no server files, a bounded size), then the
// discretization and its statistics. Stateless and thread-safe; no gRPC.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "dynsolid/service.pb.h"
#include "solver/mesh/cell_complex.h"
#include "solver/scene/build.h"
#include "server/sim_core.h"
#include "solver/solid/solid.h"

namespace dynsolid::server {

// What a CreateSession request asks to build, parsed and validated.
struct SceneRequest {
  Scene scene;
  // Folder that relative mesh files resolve against: the built-in scenes'
  // folder for a built-in scene; empty (and unused: mesh.file is rejected)
  // for scenes sent by the client.
  std::string base_dir;
  // Prefix of error messages: "builtin:block3", "scene_text" or "scene".
  std::string origin;
  // Subdivision levels to build; nullopt keeps scene.subdivision.levels.
  std::optional<int> levels;
};

// Resolves the request's scene source and levels_override. Errors:
//  - InvalidArgument naming the field: no scene source set, a scene_text
//    that does not parse or validate ("scene_text:LINE:COL: mesh.block.nx
//    ..."), mesh.file in a client's scene, levels_override outside -1..4;
//  - NotFound for an unknown builtin_scene (the message lists the names).
absl::StatusOr<SceneRequest> ResolveSceneRequest(const CreateSessionRequest& request);

struct BuildLimits {
  // Largest number of level-L cells a solid may have (estimated before
  // subdividing, see EstimateFineCells).
  int64_t max_cells = 1'000'000;
  // Threads that step each solid (Solid::Create; results do not depend on
  // it). 0: all cores but one, at least one (the other core is left to
  // streaming, gRPC and the journal; see server/README.md "Threads").
  int sim_threads = 0;
  // Largest memory a session's solid may need at its peak (its build), as
  // EstimateSessionBytes estimates it before anything is built; 0: no
  // limit.
  int64_t max_session_bytes = 0;
  // A build is stopped, and what it made freed, when it has grown the
  // process's resident memory past this many times its estimate
  // (EstimateSessionBytes), checked between its phases
  // (common::CheckBuildWatch); 0: never. The estimate errs high (a third to
  // a half above what builds were measured to take), so the default of 1.5
  // stops only a build that the estimate got badly wrong.
  double build_memory_factor = 1.5;
};

// The memory a solid of `fine_cells` cells at subdivision level `levels`
// needs at its peak (the build and its first steps), in bytes, for the
// scene's solver settings: a linear model calibrated on measured sessions
// (solid_builder.cc gives the figures). An estimate for the limit check,
// meant to err high.
int64_t EstimateSessionBytes(const Scene& scene, int64_t fine_cells, int levels);

// The level-`levels` cells of a generated control mesh (mesh.block, beam,
// tube, torus, voxels), from the generator's parameters alone: nothing is
// generated, so a huge request costs nothing to refuse. Exact for the
// hexahedral generators; for voxels an upper bound (overlapping boxes
// counted twice, subtracted ones not taken off). nullopt for meshes that
// must be read to be counted (mesh.file, mesh.inline_mesh, whose size the
// message limit already bounds). A double: the parameters can ask for more
// than 2^63 cells.
std::optional<double> GeneratedFineCells(const Scene& scene, int levels);

// The stepping threads `sim_threads` stands for (0: cores - 1, at least 1).
int SimThreads(int sim_threads);

// A built solid: its dynamics (solid::Solid, for the session's simulation
// thread only) and, sharing its lifetime, its read-only discretization.
struct BuiltSolid {
  std::shared_ptr<solid::Solid> solid;
  // Aliases solid->discretization().
  std::shared_ptr<const scene::Discretization> discretization;
  SolidStats stats;
};

// Loads the control mesh, checks the size limit, discretizes and builds the
// solid's dynamics (solid::Solid::Create). Errors:
// the solver's (InvalidArgument naming the field or mesh item, prefixed
// with request.origin), ResourceExhausted when the solid would exceed
// limits.max_cells. Can take seconds for large solids: call it off the
// RPC threads and without holding locks.
absl::StatusOr<BuiltSolid> BuildSolid(const SceneRequest& request, const BuildLimits& limits);

// Builds solids for a session made from `request` (sim_core.h
// SolidFactory): the request's own scene, or an edited scene.
SolidFactory MakeSolidFactory(SceneRequest request, BuildLimits limits);

// The number of level-`levels` cells MacCracken-Joy makes from `control`
// (after locally refining scene.mesh.refine_cells): a cell splits into one
// child per vertex, the child at a vertex of valence k has two vertices of
// valence k and 2k of valence 3 and splits likewise, and a hexahedron
// splits into 8. Exact without local refinement; with it, ignores the extra
// vertices refinement adds to the refined cells' neighbours (an estimate for
// the limit check, not a count). Cheap: no mesh is built.
int64_t EstimateFineCells(const mesh::MeshInput& control, const Scene& scene, int levels);

// The statistics of a built discretization.
SolidStats ComputeStats(const scene::Discretization& d, double build_milliseconds);

}  // namespace dynsolid::server
