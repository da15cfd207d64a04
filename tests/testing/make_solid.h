// A solid from a scene's text (built-in scene files resolve), for tests:
// null, with the failure recorded, when any step fails.
#pragma once

#include <cstdlib>
#include <memory>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::testing {

// threads: 0 for the machine's (solid::Solid::Create's default).
inline std::unique_ptr<solid::Solid> MakeSolid(const std::string& text, int threads = 0) {
  auto scene = scene::ParseScene(text, "test");
  EXPECT_OK(scene);
  if (!scene.ok()) return nullptr;
  auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(), std::nullopt);
  EXPECT_OK(d);
  if (!d.ok()) return nullptr;
  auto made = solid::Solid::Create(*scene, *std::move(d), threads);
  EXPECT_OK(made);
  return made.ok() ? *std::move(made) : nullptr;
}

// make() with DYNSOLID_THREADS set to `threads` (how a solid's pool size
// comes from the environment), unset again afterwards: for the tests that
// check the same bits for any thread count.
template <typename Make>
auto WithThreadsEnv(const char* threads, Make make) {
  setenv("DYNSOLID_THREADS", threads, 1);
  auto made = make();
  unsetenv("DYNSOLID_THREADS");
  return made;
}

}  // namespace dynsolid::testing
