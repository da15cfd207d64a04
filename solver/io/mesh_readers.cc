#include "solver/io/mesh_readers.h"

#include <filesystem>

#include "absl/strings/ascii.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {

absl::StatusOr<mesh::MeshInput> ReadMeshFile(const std::string& path) {
  const std::string ext = absl::AsciiStrToLower(std::filesystem::path(path).extension().string());
  if (ext == ".msh") return ReadGmsh(path);
  if (ext == ".vtk") return ReadVtkLegacy(path);
  return absl::InvalidArgumentError(internal::Cat(
      path, ": unknown mesh file extension '", ext,
      "': expected .msh (Gmsh 2.2 or 4.1 ASCII) or .vtk (VTK legacy ASCII unstructured grid)"));
}

}  // namespace dynsolid::io
