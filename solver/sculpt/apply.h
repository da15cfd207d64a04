// A topology edit of a live solid, end to end: the pure edit of its control
// mesh (topology.h), the edited scene (an inline control mesh, explicit
// sharp edges, the levels the solid was built with), its discretization,
// and the solid rebuilt around it with its state carried over
// (solid::Solid::Remeshed). Nothing about the network.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/cell_complex.h"
#include "solver/sculpt/topology.h"
#include "solver/solid/solid.h"

namespace dynsolid::sculpt {

struct AppliedEdit {
  // The scene the new solid stands for (Solid::TransferReport::scene): a
  // solid built from it with BuildEdited and given the new solid's
  // SaveState() is the new solid again.
  Scene scene;
  std::unique_ptr<solid::Solid> solid;
  solid::Solid::TransferReport transfer;
  std::string summary;  // "extruded 1 face by 0.2 m in 1 layer: +1 cell, +4 vertices"
  int32_t cells_before = 0, cells_after = 0;
  int32_t vertices_before = 0, vertices_after = 0;
  int32_t elements_after = 0;
  // Wall time: ApplyEdit's whole edit, rebuild included; FinishEdit's
  // finishing only (the prepared part in prepare_milliseconds).
  double milliseconds = 0;
  double prepare_milliseconds = 0;
  // Where the prepared part went (milliseconds): the edit on the control
  // mesh and the edited scene, its subdivision and element lists, the new
  // solid (its phases in solid->build_report().phases).
  struct Phases {
    double edit = 0, discretize = 0, build = 0;
  } prepare_phases;
};

// An edit prepared at rest: the edited scene and the new solid built around
// it, not yet carrying any state.
struct PreparedEdit {
  TopologyEdit edit;
  Scene scene;                 // the edited scene
  mesh::MeshInput rest_mesh;   // its control mesh
  std::unique_ptr<solid::Solid> built;
  int32_t cells_before = 0, cells_after = 0;
  int32_t vertices_before = 0, vertices_after = 0;
  int32_t elements_after = 0;
  double milliseconds = 0;
  AppliedEdit::Phases phases;
};

// Applies `edit` to `solid`, which was built from `scene` (the session's
// current scene: its settings, materials and traced points carry over).
// Errors name the edit's field and the item ("edit.extrude_faces.faces[0]:
// face 12 is interior ..."): InvalidArgument, and nothing is changed.
// ApplyEdit == FinishEdit(PrepareEdit(...)), bit for bit.
absl::StatusOr<AppliedEdit> ApplyEdit(const Scene& scene, const solid::Solid& solid,
                                      const TopologyEdit& edit);

// The expensive part (the edit at rest, the discretization, the new
// solid's matrices), which reads only what stepping leaves alone
// (solid::Solid::BuildRemeshed): a session runs it on another thread while
// `solid` goes on stepping, and holds back commands that would change the
// solid's materials or topology until FinishEdit.
absl::StatusOr<PreparedEdit> PrepareEdit(const Scene& scene, const solid::Solid& solid,
                                         const TopologyEdit& edit);
// The cheap part, at a step boundary: the edit with the current positions,
// the state carried over onto the prepared solid.
absl::StatusOr<AppliedEdit> FinishEdit(PreparedEdit prepared, const solid::Solid& solid);

// The edit alone on a control mesh at rest (`d`'s), nothing built: the new
// mesh and where its vertices and cells come from (topology.h EditResult).
// The same checks and errors as PrepareEdit's edit part.
absl::StatusOr<EditResult> EditAtRest(const scene::Discretization& d, const TopologyEdit& edit);

// The solid of an edited scene (its control mesh inline): Discretize and
// Create with `threads` stepping threads.
absl::StatusOr<std::unique_ptr<solid::Solid>> BuildEdited(const Scene& scene, int threads);

}  // namespace dynsolid::sculpt
