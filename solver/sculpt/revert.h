// The inverse of a topology edit on a live solid: its control mesh put back
// to the one before the edit, the solid's CURRENT state carried over (what
// a person's undo of their own edit does while others go on sculpting:
// server/history.h). Nothing about the network.
#pragma once

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/scene/build.h"
#include "solver/sculpt/apply.h"
#include "solver/solid/solid.h"

namespace dynsolid::sculpt {

// `solid` stands on the control mesh `edit` made from `before`'s (whose
// discretization is `d_before`). Returns the solid rebuilt on `before`'s
// mesh with its state carried over (solid::Solid::Remeshed):
//  - control points the edit kept are where they are now, with their
//    velocities; points it removed (a delete, a merge, a refinement) come
//    back at their rest position moved as the nearest kept point moved;
//  - cells the edit kept keep their materials (bit for bit where their
//    elements are the same); cells it removed come back with the scene's
//    base material;
//  - loads, drags and pins are carried over (re-selected from their
//    regions, ids kept; those with no place are dropped and named).
// The rebuilt solid stands on `before` in the form an edit leaves a scene
// in (its mesh inline, sharp edges listed, levels), so that the scene it
// reports rebuilds it (BuildEdited) and its saved states restore there.
// InvalidArgument when `solid`'s control mesh is not the edit's result
// (another edit changed it since): nothing is changed.
absl::StatusOr<AppliedEdit> RevertEdit(const Scene& before, scene::Discretization d_before,
                                       const solid::Solid& solid, const TopologyEdit& edit);

}  // namespace dynsolid::sculpt
