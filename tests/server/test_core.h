// A SimCore on a built-in scene, without a network or a session loop: the
// fixture of the server-core tests (sculpt_core_test, inspect_core_test,
// guard_core_test, undo_core_test), with commands sent as text.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "google/protobuf/text_format.h"
#include "gtest/gtest.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::server {

struct TestCore {
  Scene scene;
  SolidFactory factory;
  std::unique_ptr<SimCore> core;
  int64_t seq = 0;  // the last command seq a test sent
};

// `builtin` at `levels`, one simulation thread, default CoreOptions.
inline TestCore MakeTestCore(const std::string& builtin, int levels, bool start_paused) {
  CreateSessionRequest create;
  create.set_builtin_scene(builtin);
  create.set_levels_override(levels);
  absl::StatusOr<SceneRequest> request = ResolveSceneRequest(create);
  EXPECT_OK(request);
  TestCore c;
  c.scene = request->scene;
  BuildLimits limits;
  limits.sim_threads = 1;
  c.factory = MakeSolidFactory(*request, limits);
  absl::StatusOr<std::shared_ptr<solid::Solid>> solid = c.factory(nullptr);
  EXPECT_OK(solid);
  c.core = std::make_unique<SimCore>(*solid, CoreOptions(), start_paused, c.scene, c.factory);
  return c;
}

// Parses `text` into a command from `client` with the core's next seq and
// processes it; the reply.
inline CommandReply SendText(TestCore& c, const std::string& client, const std::string& text) {
  CommandRequest r;
  r.set_client_id(client);
  r.set_seq(++c.seq);
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, r.mutable_command())) << text;
  CommandReply reply;
  c.core->Process(r, &reply);
  return reply;
}

// Steps the core `n` times.
inline void Steps(TestCore& c, int n) {
  for (int i = 0; i < n; ++i) ASSERT_OK(c.core->StepOnce());
}

}  // namespace dynsolid::server
