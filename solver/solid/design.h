// A design's own state (scene.proto Design): the materials as painted and
// the clay's plastic rest shape, written by Solid::SaveDesign and put over a
// scene's regions by Create. A room of its own: it reads a built solid's
// layout and clay, and hands Create what it needs; it keeps no state in the
// solid. Private to solver/solid.
#pragma once

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/common/hash128.h"
#include "solver/fem/element_set.h"
#include "solver/material/plasticity.h"
#include "solver/mesh/points.h"
#include "solver/models/element_blocks.h"

namespace dynsolid::solid {

// The design's sample arrays, found by an element's rest nodes (in any
// order: the layout aligns an element's axes after the design was read),
// as models::ElementMaterials asks for them.
class DesignMaterials {
 public:
  // The arrays of `design` for the elements of `elements` at rest nodes
  // `rest`. InvalidArgument naming the field (design.elements,
  // design.sample_runs, design.materials) when the counts are not this
  // solid's, an index is out of range or a material is not physical.
  static absl::StatusOr<std::unique_ptr<DesignMaterials>> Make(const Design& design,
                                                               const fem::ElementSet& elements,
                                                               const Points& rest);
  // Element of `kind` at rest nodes x: its array (never null for an element
  // of the solid Make was given).
  const std::vector<models::MaterialPoint>* Find(int kind, const fem::NodeMatrixX3& x) const;

 private:
  std::vector<std::vector<models::MaterialPoint>> arrays_;  // by (kind, element)
  std::unordered_map<Key128, int32_t, Key128Hash> by_nodes_;
};

// The clay state `design` holds for a solid of `cells` control cells whose
// model has `units`, or nothing when it holds none. InvalidArgument naming
// the field when its counts are not those or a law is not physical.
absl::StatusOr<std::optional<material::Plasticity::State>> DesignClay(
    const Design& design, int32_t cells, material::Plasticity::Units units);

}  // namespace dynsolid::solid
