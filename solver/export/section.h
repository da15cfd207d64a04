// A cut-away (the paper's Fig. 13): where a plane cuts the solid
// at its simulated level, as triangles coloured by a field of the cells
// they cross. A pure function of the discretization and the control points
// now and at rest (and, for stiffness, the design's materials): no solid,
// no network. The server takes those at a step boundary and cuts off the
// simulation loop; a viewer draws the triangles where it clips the surface.
//
// Each level-L cell is split into tetrahedra (a fan of each face, fanned
// from its first vertex, to the cell's centroid) and each tetrahedron the
// plane crosses gives one or two triangles (marching tetrahedra), facing
// along the plane's normal. A cell's triangles carry its field value (the
// cell data below); `displacement` is interpolated from the vertices.
//
// Fields:
//  - strain: the largest engineering strain |l / l0 - 1| between two of
//    the cell's vertices (the VTU export's `strain`), dimensionless;
//  - displacement: |x - X| at the cut's points (metres);
//  - stiffness: the mean Young's modulus of the cell's elements' samples
//    (Pa), as painted;
//  - distortion: how far the cell's shape is from a rotated and uniformly
//    scaled copy of its rest shape, 1 - s_min / s_max of the singular
//    values of its best-fit deformation gradient (least squares over its
//    vertices), 0 (undistorted) to 1 (flattened).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "absl/status/statusor.h"
#include "solver/export/design_export.h"
#include "solver/mesh/points.h"
#include "solver/scene/build.h"

namespace dynsolid::exporter {

struct SectionInput {
  const scene::Discretization* discretization = nullptr;  // the solid's
  Points positions;  // control points now
  Points rest;       // control points at rest
  // For `stiffness` (MaterialFieldsOf); null: that field is refused.
  const MaterialFields* materials = nullptr;
};

struct Section {
  std::string field;
  std::string unit;               // "1", "m", "Pa"
  std::vector<float> positions;   // 9 per triangle, metres
  std::vector<float> values;      // 3 per triangle (one per vertex)
  double min = 0, max = 0;        // of the values (0, 0 when nothing is cut)
  int32_t cells_cut = 0;
};

// The fields CutSection knows.
const std::vector<std::string>& SectionFields();
// OK for one of them or "" (strain); InvalidArgument naming the field
// ("field: \"stress\" is not one of strain, ...") otherwise.
absl::Status CheckSectionField(const std::string& field);

// InvalidArgument naming the field: a zero or non-finite normal, a
// non-finite point, an unknown field (the message lists them), stiffness
// without materials, positions of the wrong size.
absl::StatusOr<Section> CutSection(const SectionInput& in, const Eigen::Vector3d& point,
                                   const Eigen::Vector3d& normal, const std::string& field);

}  // namespace dynsolid::exporter
