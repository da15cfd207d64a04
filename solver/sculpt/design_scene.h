// A solid as a scene file: the "save as" of a design (Export SCENE,
// docs/export.md). Nothing about the network.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/scene/build.h"
#include "solver/solid/solid.h"

namespace dynsolid::sculpt {

// `scene` in the form an edit leaves a scene in (apply.h): the control mesh
// of `d` inline at its rest positions (no file, generator, scale or local
// refinement left to apply), its sharp edges listed, its levels. Not
// discretized.
Scene SelfContainedScene(const Scene& scene, const scene::Discretization& d);

// The design `solid` (built from `scene`, the session's scene as it is now)
// stands for, as a scene that Create takes back:
//  - the control mesh at its rest shape (bakes included), inline, with its
//    sharp edges and the solid's levels;
//  - materials: the scene's regions, and the solid's samples as painted
//    (scene.design);
//  - clay: its flow laws, plastic offsets and plastic strain (scene.design);
//  - pins: each active fixed-region constraint as its control points;
//  - loads: the active point forces and pressures and the gravity (drags
//    and curves are a hand, not a design: left out);
//  - the floor and obstacles, traced points, solver settings as they are;
//  - at rest (no initial velocity).
// Create(result) gives a solid whose rest control points, material samples
// and clay state equal `solid`'s bit for bit (design_scene_test).
Scene DesignScene(const Scene& scene, const solid::Solid& solid);

// A scene as a scene file's text (protobuf text format, repeated numbers
// as one list per field; doubles exactly, so that it reads back to the
// same bits), after `header` (lines made into '#' comments).
std::string SceneText(const Scene& scene, const std::string& header);

}  // namespace dynsolid::sculpt
