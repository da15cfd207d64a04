// What the scene loader's tests (scene_loader_test.cc,
// scene_dynamics_test.cc) share: the matchers they use and the source tree.
#pragma once

#include <cstdlib>
#include <filesystem>

#include <gmock/gmock.h>

#include "tests/testing/status_matchers.h"

namespace dynsolid::scene {

namespace fs = std::filesystem;
using ::dynsolid::testing::StatusIs;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// The source tree: DYNSOLID_SOURCE_DIR, else the working directory.
inline fs::path SourceDir() {
  const char* dir = std::getenv("DYNSOLID_SOURCE_DIR");
  return dir != nullptr ? fs::path(dir) : fs::current_path();
}

}  // namespace dynsolid::scene
