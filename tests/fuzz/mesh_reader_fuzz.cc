// Fuzzes the volume-mesh readers (solver/io/mesh_readers.h): the Gmsh .msh
// reader (2.2 and 4.1) and the VTK legacy reader. They read files only, so
// each input is written to a temporary file of this process and read with
// io::ReadMeshFile. The first byte picks the reader (even: .msh, odd:
// .vtk); the rest is the file. A mesh that reads goes on to
// CellComplex::FromInput, as a scene naming that file would.
//
// Invariants: no crash or sanitizer report; a mesh that reads has only
// finite coordinates, every cell has faces and every index is a vertex.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "solver/io/mesh_readers.h"
#include "solver/mesh/cell_complex.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

const std::string& Path(bool vtk) {
  static const std::string msh = dynsolid::fuzz::TempPath(".msh");
  static const std::string vtk_path = dynsolid::fuzz::TempPath(".vtk");
  return vtk ? vtk_path : msh;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const bool vtk = (data[0] & 1) != 0;
  const std::string& path = Path(vtk);
  dynsolid::fuzz::WriteFile(path,
                            std::string_view(reinterpret_cast<const char*>(data) + 1, size - 1));
  absl::StatusOr<dynsolid::mesh::MeshInput> mesh = dynsolid::io::ReadMeshFile(path);
  if (!mesh.ok()) {
    FUZZ_CHECK(!absl::IsNotFound(mesh.status()), "the file just written is not found");
    return 0;
  }
  const int64_t nv = mesh->vertices.rows();
  for (int64_t i = 0; i < nv; ++i) {
    for (int a = 0; a < 3; ++a) {
      FUZZ_CHECK(std::isfinite(mesh->vertices(i, a)), "vertex %lld is not finite",
                 static_cast<long long>(i));
    }
  }
  for (size_t c = 0; c < mesh->cells.size(); ++c) {
    FUZZ_CHECK(!mesh->cells[c].empty(), "cell %zu has no faces", c);
    for (const auto& loop : mesh->cells[c]) {
      for (int32_t v : loop) {
        FUZZ_CHECK(v >= 0 && v < nv, "cell %zu names vertex %d of %lld", c, v,
                   static_cast<long long>(nv));
      }
    }
  }
  (void)dynsolid::mesh::CellComplex::FromInput(*mesh);
  return 0;
}
