// Built-in control-mesh generators: blocks, beams, tubes, tori and voxel
// solids, described by the generator messages of proto/dynsolid/scene.proto.
//
// Every generator returns a level-0 mesh::MeshInput in metres:
//  - all cells are hexahedra given as 6 quadrilateral face loops, each loop
//    oriented outward from its cell (right-hand normal points out);
//  - a face shared by two cells has the same four vertex indices in both,
//    in opposite loop order;
//  - every vertex is used by some cell (no unused vertices), and every cell
//    has positive volume.
// Vertex and cell numbering are documented per generator: they are stable,
// so scenes may refer to vertices (sharp edges) and cells (refine_cells).
//
// Parameters are validated first. Errors are InvalidArgument and name the
// field and why, e.g. "tube.inner_radius (2) must be less than
// tube.outer_radius (1)" or "block.nx must be >= 1, got 0". Sizes are capped
// at kMaxGeneratedCells cells (a MeshInput costs a few hundred bytes per
// cell); larger requests fail with the count and the cap.
#pragma once

#include <cstdint>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::scene {

// Upper bound on the number of cells a generator produces.
inline constexpr int64_t kMaxGeneratedCells = 1'000'000;
// Upper bound on the voxel generator's occupancy grid: the bounding box of
// the added boxes, in voxels (one byte each).
inline constexpr int64_t kMaxVoxelGrid = 64'000'000;
// Upper bound on the voxel generator's work: the voxels of all boxes,
// counting overlaps (each box clipped to that bounding box).
inline constexpr int64_t kMaxVoxelWork = 256'000'000;

// nx x ny x nz hexahedra spanning [origin, origin + size]; size (nx, ny, nz)
// when all its components are 0. Vertex (i, j, k), 0 <= i <= nx, is
// i + (nx+1) * (j + (ny+1) * k); cell (i, j, k) is i + nx * (j + ny * k).
absl::StatusOr<mesh::MeshInput> GenerateBlock(const BlockGenerator& block);

// A beam along x spanning [0, length] x [-width/2, width/2] x
// [-height/2, height/2]: cells_along x cells_across x cells_across
// hexahedra, numbered like a block with nx = cells_along. The clamped end of
// a cantilever is the face x = 0.
absl::StatusOr<mesh::MeshInput> GenerateBeam(const BeamGenerator& beam);

// A thick-walled tube around the z axis, periodic around the axis (the
// vertex ring closes: no seam). Vertex (l, s, k) -- layer l in 0..layers
// (inner to outer wall), segment s in 0..segments-1 (angle 2 pi s /
// segments from +x towards +y), slice k in 0..slices (z = length k /
// slices) -- is l + (layers+1) * (s + segments * k). Cell (l, s, k) is
// l + layers * (s + segments * k). The radii at z are scaled by
// 1 + (end_scale - 1) z / length.
absl::StatusOr<mesh::MeshInput> GenerateTube(const TubeGenerator& tube);

// A solid torus around the z axis with a square cross section, periodic
// around the axis. Vertex (i, s, j) -- i in 0..cross radially outward, s in
// 0..segments-1 around the axis, j in 0..cross upward -- sits at radius
// major_radius + tube_half_width (2i/cross - 1) and height
// tube_half_width (2j/cross - 1); its index is
// i + (cross+1) * (j + (cross+1) * s). Cell (i, s, j) is
// i + cross * (j + cross * s).
absl::StatusOr<mesh::MeshInput> GenerateTorus(const TorusGenerator& torus);

// Unit voxels [x, x+1) x [y, y+1) x [z, z+1) in the union of the added
// boxes minus the subtracted ones (applied in order), scaled by cell_size.
// Cells are numbered in increasing (z, y, x) order; vertices in order of
// first use by the cells (shared grid vertices are merged, unused ones are
// never created). Rejects an empty result, and a result whose boundary is
// not a manifold (voxels that touch only along an edge or at a corner),
// naming the grid vertex.
absl::StatusOr<mesh::MeshInput> GenerateVoxels(const VoxelGenerator& voxels);

// Overloads, so callers can dispatch on the oneof.
inline absl::StatusOr<mesh::MeshInput> Generate(const BlockGenerator& g) { return GenerateBlock(g); }
inline absl::StatusOr<mesh::MeshInput> Generate(const BeamGenerator& g) { return GenerateBeam(g); }
inline absl::StatusOr<mesh::MeshInput> Generate(const TubeGenerator& g) { return GenerateTube(g); }
inline absl::StatusOr<mesh::MeshInput> Generate(const TorusGenerator& g) { return GenerateTorus(g); }
inline absl::StatusOr<mesh::MeshInput> Generate(const VoxelGenerator& g) { return GenerateVoxels(g); }

// Parameter checks alone (no mesh is built), with the same messages as the
// generators. The voxel check cannot see an empty or non-manifold result:
// only GenerateVoxels can.
absl::Status ValidateBlock(const BlockGenerator& block);
absl::Status ValidateBeam(const BeamGenerator& beam);
absl::Status ValidateTube(const TubeGenerator& tube);
absl::Status ValidateTorus(const TorusGenerator& torus);
absl::Status ValidateVoxels(const VoxelGenerator& voxels);

}  // namespace dynsolid::scene
