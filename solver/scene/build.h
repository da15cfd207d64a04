// Building a solid's discretization from a scene: control mesh, sharp tags,
// local refinement, MacCracken-Joy levels, element classification and the
// FEM node matrix. Builds only what the scene asks for.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/fem/element_set.h"
#include "solver/mesh/cell_complex.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::scene {

// The static part of a solid: everything that changes only with topology.
struct Discretization {
  std::string name;
  // Control mesh (after local refinement) -> level-L mesh and tags.
  // hierarchy.a is left empty: A is the first rows of node_matrix.
  subdivision::Hierarchy hierarchy;
  fem::ElementSet elements;
  // FEM nodes (level-L vertices, then virtual nodes) x control points:
  // d = node_matrix * p.
  subdivision::SparseMatrix node_matrix;
  int32_t input_cells = 0;            // control cells before local refinement
  int32_t locally_refined_cells = 0;  // mesh.refine_cells
  int32_t sharp_control_edges = 0;    // tagged control edges
  // Per edge of the control mesh (after local refinement): tagged sharp.
  std::vector<uint8_t> control_sharp;

  const mesh::CellComplex& control() const { return *hierarchy.control; }
  const mesh::CellComplex& fine() const { return *hierarchy.fine; }
};

// Wall-clock time of each build phase, in milliseconds (reported, never
// asserted on).
struct BuildTimings {
  double load_ms = 0, validate_ms = 0, local_refine_ms = 0, subdivide_ms = 0,
         classify_ms = 0;
};

// Builds from an already generated or loaded level-0 mesh. `levels`
// overrides scene.subdivision.levels when set. Errors are InvalidArgument
// naming the field or mesh item at fault.
absl::StatusOr<Discretization> Discretize(const Scene& scene, const mesh::MeshInput& control,
                                          std::optional<int> levels,
                                          BuildTimings* timings = nullptr);
// The same from the complex FromInput built of that mesh (a topology edit
// has built and checked it already).
absl::StatusOr<Discretization> Discretize(const Scene& scene, mesh::CellComplex base,
                                          std::optional<int> levels,
                                          BuildTimings* timings = nullptr);

// Loads the scene's control mesh (ControlMeshInput) and discretizes it.
absl::StatusOr<Discretization> BuildDiscretization(const Scene& scene, std::string_view base_dir,
                                                   std::optional<int> levels,
                                                   BuildTimings* timings = nullptr);

}  // namespace dynsolid::scene
