// The stability guard seen from a session's core (SimCore): a blow-up is
// caught within physics, rolled back, pauses the session and says why; the
// message goes when the state it spoke of goes (a revert to the scene, a
// good step) and comes back with it (the revert's undo).
#include <memory>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "google/protobuf/text_format.h"
#include "server/sim_core.h"
#include "tests/server/test_core.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;

CommandReply Send(TestCore& s, const std::string& text) { return SendText(s, "sculptor", text); }

// The diagonal of the control points' bounding box.
double Extent(const TestCore& s) {
  const Points& p = s.core->solid().control_positions();
  return (p.colwise().maxCoeff() - p.colwise().minCoeff()).norm();
}

// block3 (3 m, E = 100 kPa) inflated by 2e5 Pa on its top face: a static
// estimate of 2 L, within the load bound of 10 L, but far past what the
// corotational cells hold (they invert). The follower pressure pays for the
// blow-up, so the energy ledger alone let it run to 1e37 J before it
// stopped the session (233 steps); the extent check stops it at 10 L.
TEST(GuardCoreTest, ABlowUpIsCaughtRolledBackAndItsMessageGoesWithItsState) {
  TestCore s = MakeTestCore("block3", 2, /*start_paused=*/false);
  const double rest = Extent(s);
  const CommandReply add = Send(s, R"(add_pressure {
      region { box { min { x: -0.1 y: -0.1 z: 2.99 } max { x: 3.1 y: 3.1 z: 3.1 } } }
      pascals: 2e5 })");
  ASSERT_EQ(add.code(), 0) << add.message();
  absl::Status failed;
  int steps = 0;
  for (; steps < 2000 && failed.ok(); ++steps) failed = s.core->StepOnce();
  ASSERT_FALSE(failed.ok()) << "2e5 Pa ran " << steps << " steps without the guard";
  EXPECT_THAT(std::string(failed.message()), HasSubstr("blew up"));
  EXPECT_THAT(std::string(failed.message()), HasSubstr("state restored to the step's start"));
  // Rolled back to the failed step's start: within the bound, finite, paused.
  EXPECT_TRUE(s.core->solid().control_positions().allFinite());
  EXPECT_LE(Extent(s), 10 * rest);
  EXPECT_TRUE(s.core->paused());
  EXPECT_FALSE(s.core->WantsStep());
  const std::string said = s.core->last_error();
  EXPECT_THAT(said, HasSubstr(absl::StrCat("step ", s.core->steps() + 1, " failed")));
  EXPECT_THAT(said, HasSubstr("blew up"));
  EXPECT_THAT(said, HasSubstr("revert_to_scene"));  // what a person can do

  // Resuming as it is fails again at once, and says so for that step.
  ASSERT_EQ(Send(s, "resume {}").code(), 0);
  EXPECT_FALSE(s.core->StepOnce().ok());
  EXPECT_THAT(s.core->last_error(), HasSubstr("blew up"));

  // Undoing the pressure takes the load away from the solid as it is now
  // (undo is per person and keeps everyone's motion, server/history.h):
  // the state the message spoke of stays, and so does the message.
  const CommandReply undo = Send(s, "undo {}");
  ASSERT_EQ(undo.code(), 0) << undo.message();
  EXPECT_TRUE(s.core->solid().ActiveLoads().empty());
  EXPECT_THAT(s.core->last_error(), HasSubstr("blew up"));
  // A revert to the scene takes that state away: the message goes with it,
  // and the block steps again and stays at rest.
  ASSERT_EQ(Send(s, "revert_to_scene {}").code(), 0);
  EXPECT_EQ(s.core->last_error(), "");
  ASSERT_EQ(Send(s, "resume {}").code(), 0);
  for (int i = 0; i < 200; ++i) ASSERT_OK(s.core->StepOnce());
  EXPECT_EQ(s.core->last_error(), "");
  EXPECT_LE(Extent(s), 1.01 * rest);
}

// The message speaks of a state: the undo of the revert that took the
// blown-up state away brings it back, and the failure with it at its
// first step (on the session's clock, 50 steps later).
TEST(GuardCoreTest, UndoingTheRevertBringsTheBlownUpStateBackAndItFailsAgainAtOnce) {
  TestCore s = MakeTestCore("block3", 2, /*start_paused=*/false);
  const CommandReply add = Send(s, R"(add_pressure {
      region { box { min { x: -0.1 y: -0.1 z: 2.99 } max { x: 3.1 y: 3.1 z: 3.1 } } }
      pascals: 2e5 })");
  ASSERT_EQ(add.code(), 0) << add.message();
  absl::Status failed;
  for (int i = 0; i < 2000 && failed.ok(); ++i) failed = s.core->StepOnce();
  ASSERT_FALSE(failed.ok());
  const int64_t failed_at = s.core->steps() + 1;
  ASSERT_EQ(Send(s, "revert_to_scene {}").code(), 0);
  ASSERT_EQ(Send(s, "resume {}").code(), 0);
  for (int i = 0; i < 50; ++i) ASSERT_OK(s.core->StepOnce());
  EXPECT_EQ(s.core->last_error(), "");
  const CommandReply undo = Send(s, "undo {}");
  ASSERT_EQ(undo.code(), 0) << undo.message();
  ASSERT_EQ(Send(s, "resume {}").code(), 0);
  const absl::Status again = s.core->StepOnce();
  ASSERT_FALSE(again.ok()) << "the state that failed at step " << failed_at << " is back";
  EXPECT_THAT(std::string(again.message()), HasSubstr("blew up"));
  EXPECT_THAT(s.core->last_error(), HasSubstr(absl::StrCat("step ", failed_at + 50, " failed")));
  EXPECT_TRUE(s.core->paused());
}

}  // namespace
}  // namespace dynsolid::server
