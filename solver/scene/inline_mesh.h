// Control meshes given inline in a scene (scene.proto InlineMesh): what a
// sculpted solid's mesh becomes after a topology edit, and what a client may
// send instead of a generator.
#pragma once

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/cell_complex.h"

namespace dynsolid::scene {

// The mesh an InlineMesh describes. InvalidArgument naming the field and the
// item when the counts do not add up ("mesh.inline_mesh.face_sizes: 3 faces
// listed by cell_face_counts, 2 sizes given"), an index is out of range or
// the mesh is larger than kMaxGeneratedCells. Topology and geometry are
// validated later, by mesh::CellComplex::FromInput.
absl::StatusOr<mesh::MeshInput> MeshFromInline(const InlineMesh& m);

// The inverse: `mesh` as an InlineMesh (cells, faces and loops in order).
InlineMesh InlineFromMesh(const mesh::MeshInput& mesh);

}  // namespace dynsolid::scene
