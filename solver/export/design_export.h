// Export of a design: the solid's current shape, at any subdivision level,
// in the formats other tools open (docs/export.md). A pure function of the
// control mesh (its topology and sharp tags), the control points now and
// at rest: no solid, no network. The server takes those at a step boundary
// and calls this off the simulation loop.
//
// The level is the caller's choice, not only the simulated one: the
// control mesh is subdivided `level` times (MacCracken-Joy, the sharp tags
// kept), and the limit-approximating vertices are A p for the control
// points p, the same map the simulation uses at its own level. So the
// export at the simulated level is exactly the surface watchers see.
//
// Formats:
//  - surface (the boundary's faces, outward loops): OBJ (ASCII), binary
//    STL (triangulated), binary PLY, glTF 2.0 binary (.glb, with normals;
//    optionally a field as vertex colours);
//  - volume: VTU (VTK XML, ASCII) with one cell per finite element of that
//    level and the point fields below.
// Fields (PLY and VTU carry them; glb can colour by one): `displacement`
// (A (p - p_rest), m, 3 components) and `displacement_magnitude`. The VTU
// has cell data too: `strain` (the largest engineering strain |l / l0 - 1|
// between any two of the cell's nodes, as the surface's strain field is
// made), `element_kind`, `control_cell`, and with DesignInput::materials
// `young_modulus`, `density` and `plastic_strain`.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/boundary.h"
#include "solver/mesh/points.h"
#include "solver/scene/build.h"

namespace dynsolid::exporter {

enum class Format { kObj, kStl, kPly, kGlb, kVtu };

// "obj", "stl", "ply", "glb", "vtu".
const char* Extension(Format f);
// model/obj, model/stl, ... (the IANA media types; VTU has none:
// application/xml).
const char* MediaType(Format f);

// A design's materials for the volume export's cell data: per finite
// element of the solid (at its own level; kinds in order cubic, trilinear,
// pyramid, the solid's element order) and per control cell, the mean
// Young's modulus (Pa) and density (kg/m^3) over the quadrature samples,
// and the accumulated plastic strain (the largest over a control cell's
// flow units; 0 without clay).
struct MaterialFields {
  int level = -1;  // the solid's level
  std::vector<double> young, density, plastic;                 // per element
  std::vector<double> cell_young, cell_density, cell_plastic;  // per control cell
};

// From a solid's discretization and its design (solid::Solid::SaveDesign).
// InvalidArgument when the design is not for that discretization.
absl::StatusOr<MaterialFields> MaterialFieldsOf(const scene::Discretization& d,
                                                const Design& design);

struct DesignInput {
  const scene::Discretization* discretization = nullptr;  // control mesh, sharp tags
  Points positions;  // control points now (#control x 3)
  Points rest;       // control points at rest (#control x 3)
  // The VTU's material cell data (null: none): at the solid's own level
  // each element's, at another level its control cell's.
  const MaterialFields* materials = nullptr;
};

struct ExportOptions {
  Format format = Format::kGlb;
  int level = 0;
  // glb: the field shown as vertex colours ("" none; "displacement").
  std::string color_field;
  // Refused above this many cells at the export level (the subdivision's
  // memory grows 8 times per level).
  int64_t max_cells = 2'000'000;
};

struct Exported {
  std::string bytes;
  int64_t cells = 0, surface_faces = 0, vertices = 0;
};

// InvalidArgument naming the field: a level out of [0, 6], more cells than
// max_cells at that level (with the count), positions of the wrong size or
// non-finite, an unknown colour field.
absl::StatusOr<Exported> ExportDesign(const DesignInput& in, const ExportOptions& options);

// The boundary surface of ExportDesign's surface formats (options.level;
// its positions now, with the fields `displacement` and
// `displacement_magnitude`), for callers that write it themselves (an
// animation's frames). The same errors; `cells` and `vertices` (optional)
// get the counts at that level.
absl::StatusOr<mesh::BoundarySurface> DesignSurface(const DesignInput& in,
                                                    const ExportOptions& options,
                                                    int64_t* cells = nullptr,
                                                    int64_t* vertices = nullptr);

}  // namespace dynsolid::exporter
