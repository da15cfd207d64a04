// Fuzzes the scene text parser: scene::ParseScene (protobuf text format,
// then ValidateScene with positions in the messages), and for scenes that
// pass and carry their own small mesh (inline_mesh, or a block of at most
// 512 cells), ControlMeshInput (MeshFromInline) and CellComplex::FromInput,
// which validates the topology a client sends. mesh.file scenes are not
// read (a client's scene may not name a file: ResolveSceneRequest refuses
// it; the file readers have their own target).
//
// Invariants: no crash or sanitizer report; an accepted scene, printed in
// text format and parsed again, is accepted again and equal.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>

#include "solver/mesh/cell_complex.h"
#include "solver/scene/inline_mesh.h"
#include "solver/scene/scene_loader.h"
#include "tests/fuzz/fuzz_proto.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

using dynsolid::ControlMesh;
using dynsolid::Scene;

bool SmallOwnMesh(const Scene& scene) {
  const ControlMesh& m = scene.mesh();
  if (m.source_case() == ControlMesh::kInlineMesh) return true;
  if (m.source_case() == ControlMesh::kBlock) {
    const int64_t nx = m.block().nx(), ny = m.block().ny(), nz = m.block().nz();
    return nx >= 0 && ny >= 0 && nz >= 0 && nx <= 512 && ny <= 512 && nz <= 512 &&
           (nx == 0 ? 3 : nx) * (ny == 0 ? 3 : ny) * (nz == 0 ? 3 : nz) <= 512;
  }
  return false;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  dynsolid::fuzz::QuietProtobuf();
  const std::string dir = dynsolid::fuzz::SeedDir();
  if (dir.empty()) return 0;
  // The built-in scenes, as their text (scenes/*.textproto).
  for (const std::string& name : dynsolid::scene::BuiltinSceneNames()) {
    auto text = dynsolid::scene::BuiltinSceneText(name);
    if (text.ok()) dynsolid::fuzz::WriteFile(dir + "/builtin_" + name, *text);
  }
  // A small block's control mesh given inline (what a client may send).
  Scene scene;
  scene.set_name("inline");
  scene.mutable_mesh()->mutable_block()->set_nx(2);
  scene.mutable_mesh()->mutable_block()->set_ny(1);
  scene.mutable_mesh()->mutable_block()->set_nz(1);
  scene.mutable_subdivision()->set_levels(1);
  absl::StatusOr<dynsolid::mesh::MeshInput> input = dynsolid::scene::ControlMeshInput(scene, "");
  if (!input.ok()) std::abort();
  *scene.mutable_mesh()->mutable_inline_mesh() = dynsolid::scene::InlineFromMesh(*input);
  std::string text;
  google::protobuf::TextFormat::PrintToString(scene, &text);
  dynsolid::fuzz::WriteFile(dir + "/inline_block2", text);
  std::exit(0);
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<Scene> scene = dynsolid::scene::ParseScene(text, "fuzz");
  if (!scene.ok()) {
    FUZZ_CHECK(!scene.status().message().empty(), "an error without a message");
    return 0;
  }
  FUZZ_CHECK(dynsolid::scene::ValidateScene(*scene).ok(), "ParseScene returned an invalid scene");

  // Round trip through the text format.
  std::string printed;
  FUZZ_CHECK(google::protobuf::TextFormat::PrintToString(*scene, &printed), "cannot print");
  absl::StatusOr<Scene> again = dynsolid::scene::ParseScene(printed, "fuzz-printed");
  FUZZ_CHECK(again.ok(), "a printed accepted scene is refused: %s\n%s",
             std::string(again.status().message()).c_str(), printed.c_str());
  FUZZ_CHECK(google::protobuf::util::MessageDifferencer::Equals(*scene, *again),
             "the printed scene parses to another scene");

  if (SmallOwnMesh(*scene)) {
    absl::StatusOr<dynsolid::mesh::MeshInput> input =
        dynsolid::scene::ControlMeshInput(*scene, "");
    if (input.ok()) (void)dynsolid::mesh::CellComplex::FromInput(*input);
  }
  return 0;
}
