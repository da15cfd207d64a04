// Server pieces without a network: status mapping, tokens, the cell
// estimate behind max_cells, request resolution, the registry and the
// build work queue.
#include <pthread.h>

#include <algorithm>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "server/grpc_status.h"
#include "server/session_registry.h"
#include "server/solid_builder.h"
#include "server/tokens.h"
#include "server/thread_priority.h"
#include "server/work_queue.h"
#include "solver/scene/scene_loader.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::server {
namespace {

using ::dynsolid::testing::StatusIs;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::MatchesRegex;
using ::testing::StartsWith;

TEST(ToGrpcStatusTest, KeepsCodeAndMessage) {
  EXPECT_TRUE(ToGrpcStatus(absl::OkStatus()).ok());
  // absl and gRPC share the canonical numbering 1..16.
  for (int code = 1; code <= 16; ++code) {
    const absl::Status in(static_cast<absl::StatusCode>(code), "what and where");
    const grpc::Status out = ToGrpcStatus(in);
    EXPECT_EQ(static_cast<int>(out.error_code()), code) << in;
    EXPECT_EQ(out.error_message(), "what and where");
  }
  EXPECT_EQ(ToGrpcStatus(absl::Status(static_cast<absl::StatusCode>(99), "odd")).error_code(),
            grpc::StatusCode::UNKNOWN);
}

TEST(TokensTest, RandomHexHasTheRequestedBitsAndDoesNotRepeat) {
  RandomHex random;
  std::set<std::string> seen;
  for (int i = 0; i < 1000; ++i) {
    const std::string token = random.Next(kTokenBits);
    ASSERT_THAT(token, MatchesRegex("[0-9a-f]{32}"));
    EXPECT_TRUE(seen.insert(token).second) << "repeated token " << token;
  }
  EXPECT_THAT(random.Next(kSessionIdBits), MatchesRegex("[0-9a-f]{16}"));
}

TEST(TokensTest, TokensEqualComparesWholeStrings) {
  EXPECT_TRUE(TokensEqual("00ff", "00ff"));
  EXPECT_FALSE(TokensEqual("00fe", "00ff"));
  EXPECT_FALSE(TokensEqual("00f", "00ff"));
  EXPECT_FALSE(TokensEqual("", "00ff"));
  EXPECT_FALSE(TokensEqual("00ff0", "00ff"));
}

TEST(ResolveSceneRequestTest, ChecksSourceLevelsAndFiles) {
  CreateSessionRequest request;
  EXPECT_THAT(ResolveSceneRequest(request),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("scene_source")));

  request.set_builtin_scene("mixed");  // a built-in scene may read its own mesh file
  absl::StatusOr<SceneRequest> resolved = ResolveSceneRequest(request);
  ASSERT_OK(resolved);
  EXPECT_EQ(resolved->origin, "builtin:mixed");
  EXPECT_EQ(resolved->base_dir, scene::BuiltinSceneDir());
  EXPECT_FALSE(resolved->levels.has_value());

  request.set_levels_override(-1);
  ASSERT_OK(ResolveSceneRequest(request));
  EXPECT_FALSE(ResolveSceneRequest(request)->levels.has_value());
  request.set_levels_override(3);
  EXPECT_EQ(ResolveSceneRequest(request)->levels, 3);
  request.set_levels_override(-2);
  EXPECT_THAT(ResolveSceneRequest(request),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("levels_override"), HasSubstr("got -2"))));

  // The model: the scene's, or the one asked for; nothing else.
  request.clear_levels_override();
  request.set_builtin_scene("block3");
  EXPECT_EQ(ResolveSceneRequest(request)->scene.solver().model(), SolverSettings::COROTATIONAL);
  EXPECT_EQ(ResolveSceneRequest(request)->scene.solver().corotation(), SolverSettings::CONTROL_CELL);
  // The local-frame model has no corotation setting: the override clears it.
  request.set_model_override(SolverSettings::LOCAL_FRAME);
  EXPECT_EQ(ResolveSceneRequest(request)->scene.solver().model(), SolverSettings::LOCAL_FRAME);
  EXPECT_EQ(ResolveSceneRequest(request)->scene.solver().corotation(),
            SolverSettings::COROTATION_DEFAULT);
  request.set_model_override(SolverSettings::COROTATIONAL);
  EXPECT_EQ(ResolveSceneRequest(request)->scene.solver().model(), SolverSettings::COROTATIONAL);
  request.set_model_override(static_cast<SolverSettings::Model>(7));
  EXPECT_THAT(ResolveSceneRequest(request),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(HasSubstr("model_override"), HasSubstr("got 7"))));
  request.clear_model_override();

  // The text of the same built-in scene is refused: it names a file.
  absl::StatusOr<std::string_view> text = scene::BuiltinSceneText("mixed");
  ASSERT_OK(text);
  request.clear_levels_override();
  request.set_scene_text(std::string(*text));
  EXPECT_THAT(ResolveSceneRequest(request),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       AllOf(StartsWith("scene_text: mesh.file"), HasSubstr("generator"))));
}

TEST(BuildSolidTest, RefusesSolidsOverTheCellLimit) {
  CreateSessionRequest request;
  request.set_builtin_scene("block3");
  absl::StatusOr<SceneRequest> resolved = ResolveSceneRequest(request);
  ASSERT_OK(resolved);
  EXPECT_THAT(BuildSolid(*resolved, BuildLimits{1727}),
              StatusIs(absl::StatusCode::kResourceExhausted,
                       AllOf(StartsWith("builtin:block3: "), HasSubstr("1728 cells"))));
  absl::StatusOr<BuiltSolid> built = BuildSolid(*resolved, BuildLimits{1728});
  ASSERT_OK(built);
  EXPECT_EQ(built->stats.cells(), 1728);
  EXPECT_EQ(built->discretization->fine().num_cells(), 1728);
}

TEST(SessionRegistryTest, CreateGetCloseWithoutANetwork) {
  RegistryOptions options;
  options.max_sessions = 2;
  SessionRegistry registry(options);
  CreateSessionRequest request;
  request.set_builtin_scene("block3");
  request.set_levels_override(0);
  absl::StatusOr<std::shared_ptr<const SolidSession>> a = registry.Create(request);
  ASSERT_OK(a);
  EXPECT_EQ((*a)->stats().cells(), 27);
  const Session proto = (*a)->ToProto();
  ASSERT_OK(registry.Get((*a)->id(), proto.token()));
  EXPECT_THAT(registry.Get((*a)->id(), "x"),
              StatusIs(absl::StatusCode::kPermissionDenied, HasSubstr((*a)->id())));
  EXPECT_EQ(registry.size(), 1);

  // A creation whose client went away is never opened.
  EXPECT_THAT(registry.Create(request, [] { return true; }),
              StatusIs(absl::StatusCode::kCancelled, HasSubstr("cancelled")));
  EXPECT_EQ(registry.size(), 1);

  ASSERT_OK(registry.Close((*a)->id(), proto.token()));
  EXPECT_EQ(registry.size(), 0);
  // The caller's reference keeps the closed session's solid alive.
  EXPECT_EQ((*a)->discretization()->fine().num_cells(), 27);

  registry.StopAccepting();
  EXPECT_THAT(registry.Create(request), StatusIs(absl::StatusCode::kUnavailable, HasSubstr("shutting down")));
}

TEST(WorkQueueTest, RunsEveryTaskOnceAndCancelsQueuedOnesOnStop) {
  WorkQueue queue(1);
  absl::Notification release;
  absl::Notification started;
  std::atomic<int> ran{0}, cancelled{0};
  // Occupy the only worker, then queue three more.
  queue.Post([&](bool run) {
    started.Notify();
    release.WaitForNotification();
    ran += run;
  });
  started.WaitForNotification();
  for (int i = 0; i < 3; ++i) queue.Post([&](bool run) { (run ? ran : cancelled) += 1; });
  queue.Stop();
  EXPECT_EQ(cancelled.load(), 3);
  queue.Post([&](bool run) { (run ? ran : cancelled) += 1; });  // after Stop: cancelled at once
  EXPECT_EQ(cancelled.load(), 4);
  release.Notify();
  queue.Join();
  EXPECT_EQ(ran.load(), 1);
}

TEST(WorkQueueTest, WorkersCarryTheirNameAndTheLoweredPriority) {
  const int base = ThisThreadNice();
  WorkQueue queue(2, "encode", 3);
  absl::Mutex mu;
  std::vector<std::pair<std::string, int>> seen;  // (thread name, nice) per task
  for (int i = 0; i < 6; ++i) {
    queue.Post([&](bool run) {
      char name[16] = {};
      pthread_getname_np(pthread_self(), name, sizeof(name));
      absl::MutexLock lock(&mu);
      seen.emplace_back(run ? name : "cancelled", ThisThreadNice());
    });
  }
  {
    absl::MutexLock lock(&mu);
    mu.Await(absl::Condition(
        +[](std::vector<std::pair<std::string, int>>* v) { return v->size() == 6; }, &seen));
  }
  queue.Join();
  for (const auto& [name, nice] : seen) {
    EXPECT_EQ(name, "encode");
    EXPECT_EQ(nice, std::min(19, base + 3)) << "base nice " << base;
  }
  // The creating thread keeps its priority.
  EXPECT_EQ(ThisThreadNice(), base);
}

TEST(ThreadPriorityTest, IdlePolicyIsPerThreadAndInherited) {
  ASSERT_FALSE(ThisThreadIsIdle());
  std::thread([] {
    ASSERT_TRUE(MakeThisThreadIdle().ok());
    EXPECT_TRUE(ThisThreadIsIdle());
    std::thread([] { EXPECT_TRUE(ThisThreadIsIdle()); }).join();
  }).join();
  EXPECT_FALSE(ThisThreadIsIdle());
  // An idle work queue: its workers, not the creator.
  WorkQueue queue(1, "encode", 0, /*idle=*/true);
  absl::Notification done;
  bool idle = false;
  queue.Post([&](bool run) {
    idle = run && ThisThreadIsIdle();
    done.Notify();
  });
  done.WaitForNotification();
  queue.Join();
  EXPECT_TRUE(idle);
  EXPECT_FALSE(ThisThreadIsIdle());
}

TEST(ThreadPriorityTest, LowersOnlyTheCallingThreadWithinRange) {
  const int base = ThisThreadNice();
  std::thread([base] {
    EXPECT_THAT(LowerThisThreadPriority(20),
                StatusIs(absl::StatusCode::kInvalidArgument,
                         "a thread's nice value can be raised by 0..19, got 20"));
    EXPECT_THAT(LowerThisThreadPriority(-1),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("got -1")));
    EXPECT_EQ(ThisThreadNice(), base);  // refusals change nothing
    EXPECT_TRUE(LowerThisThreadPriority(0).ok());
    EXPECT_EQ(ThisThreadNice(), base);
    ASSERT_TRUE(LowerThisThreadPriority(2).ok());
    EXPECT_EQ(ThisThreadNice(), std::min(19, base + 2));
    ASSERT_TRUE(LowerThisThreadPriority(19).ok());
    EXPECT_EQ(ThisThreadNice(), 19);  // capped
    // A thread started from here inherits the value.
    std::thread([] { EXPECT_EQ(ThisThreadNice(), 19); }).join();
  }).join();
  EXPECT_EQ(ThisThreadNice(), base);
}

}  // namespace
}  // namespace dynsolid::server
