// The live session over loopback gRPC against an in-process server: the
// simulation loop, Commands (every invalid kind, exactly-once resends, rate
// limits), tokens, stats, topology edits, drags and inspection. Watch has
// its own file (watch_live_test.cc), so have persistence across a restart
// and TLS (persist_live_test.cc).
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <chrono>
#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "google/protobuf/text_format.h"

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "dynsolid/journal.pb.h"
#include "dynsolid/service.grpc.pb.h"
#include "live_client.h"
#include "live_fixture.h"
#include "server/journal.h"
#include "server/server.h"
#include "server/surface_codec.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;
TEST_F(LiveTest, InvalidCommandsOfEveryKindAreRejectedWithTheirMessageAndChangeNothing) {
  // Session a gets every invalid command between valid ones; session b only
  // the valid ones, at the same steps. Their states must stay bit-identical.
  const Session a = Create("block3", 1, true);
  const Session b = Create("block3", 1, true);
  CommandStream ca(*stub_, a, "invalid");
  CommandStream cb(*stub_, b, "invalid");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();

  ASSERT_EQ(ca.Send(1, ForceCommand(1.5, 1.5, 3, 1e4, 0, 0)).code(), 0);
  ASSERT_EQ(cb.Send(1, ForceCommand(1.5, 1.5, 3, 1e4, 0, 0)).code(), 0);
  ASSERT_EQ(ca.Send(2, StepCommand(10)).code(), 0);
  ASSERT_EQ(cb.Send(2, StepCommand(10)).code(), 0);
  ASSERT_EQ(InspectAt(*stub_, a, 10).step(), 10);
  ASSERT_EQ(InspectAt(*stub_, b, 10).step(), 10);

  struct Case {
    std::string what;
    Command command;
    int code;
    std::string message;
  };
  std::vector<Case> cases;
  cases.push_back({"force outside the solid", ForceCommand(10, 10, 10, 1, 0, 0), 3,
                   "command.add_point_force.position"});
  cases.push_back({"nan force", ForceCommand(1, 1, 1, nan, 0, 0), 3,
                   "command.add_point_force.force.x must be finite, got nan"});
  {
    Command c;
    c.mutable_add_pressure()->mutable_region()->mutable_sphere()->mutable_center()->set_x(50);
    c.mutable_add_pressure()->mutable_region()->mutable_sphere()->set_radius(0.1);
    c.mutable_add_pressure()->set_pascals(100);
    cases.push_back({"pressure selecting no face", c, 3, "command.add_pressure"});
    Command z;
    z.mutable_add_pressure()->mutable_region()->mutable_sphere()->set_radius(10);
    cases.push_back({"zero pressure", z, 3, "command.add_pressure.pascals must be non-zero"});
  }
  {
    Command c;
    c.mutable_set_gravity()->set_z(-inf);
    cases.push_back({"infinite gravity", c, 3, "command.set_gravity.z must be finite, got -inf"});
  }
  {
    Command c;
    c.mutable_remove_load()->set_load_id(999);
    cases.push_back({"unknown load", c, 5, "command.remove_load.load_id: load id 999 not found"});
  }
  {
    Command c;
    c.mutable_fix_region()->mutable_sphere()->mutable_center()->set_z(-40);
    c.mutable_fix_region()->mutable_sphere()->set_radius(0.5);
    cases.push_back({"fix selecting nothing", c, 3, "command.fix_region selects no control point"});
    Command n;
    n.mutable_fix_region()->mutable_box()->mutable_max()->set_y(nan);
    cases.push_back({"nan fix box", n, 3, "command.fix_region.box.max.y must be finite, got nan"});
  }
  {
    Command c;
    c.mutable_unfix()->set_constraint_id(77);
    cases.push_back({"unknown constraint", c, 5,
                     "command.unfix.constraint_id: constraint id 77 not found"});
  }
  {
    Command c;
    c.mutable_paint_material()->mutable_region()->mutable_sphere()->set_radius(1);
    c.mutable_paint_material()->mutable_material()->set_young_modulus(2e5);
    c.mutable_paint_material()->set_strength(0);
    cases.push_back({"paint strength 0", c, 3,
                     "command.paint_material.strength must be in (0, 1], got 0"});
    Command m;
    m.mutable_paint_material()->mutable_region()->mutable_sphere()->set_radius(1);
    m.mutable_paint_material()->set_strength(1);
    cases.push_back({"paint setting nothing", m, 3, "command.paint_material.material sets no field"});
  }
  cases.push_back({"step 0", StepCommand(0), 3, "command.step.count: must be in [1, 1000000], got 0"});
  cases.push_back({"step too many", StepCommand(2'000'000), 3, "command.step.count"});
  {
    Command c;
    c.mutable_save();
    cases.push_back({"save without a data dir", c, 9, "command.save: this server runs without"});
  }
  cases.push_back({"no kind", Command(), 3, "command: no command kind is set"});
  // (pause and resume have no invalid form.)

  uint64_t seq = 3;
  std::vector<std::pair<uint64_t, CommandReply>> rejected;
  for (const Case& c : cases) {
    const CommandReply r = ca.Send(seq, c.command);
    EXPECT_EQ(r.code(), c.code) << c.what << ": " << r.message();
    EXPECT_THAT(r.message(), StartsWith(c.message)) << c.what;
    EXPECT_EQ(r.applied_step(), 10) << c.what;
    EXPECT_FALSE(r.duplicate());
    rejected.emplace_back(seq, r);
    ++seq;
  }
  // Envelope errors are answered on arrival and never recorded.
  {
    CommandRequest bad;
    bad.set_seq(seq);
    *bad.mutable_command() = StepCommand(1);
    ASSERT_TRUE(ca.WriteRaw(bad));
    CommandReply r;
    ASSERT_TRUE(ca.Read(&r));
    EXPECT_EQ(r.code(), 3);
    EXPECT_EQ(r.message(), "client_id: must have 1 to 64 characters, got 0");
    EXPECT_EQ(r.applied_step(), -1);
    bad.set_client_id("invalid");
    bad.set_seq(0);
    ASSERT_TRUE(ca.WriteRaw(bad));
    ASSERT_TRUE(ca.Read(&r));
    EXPECT_EQ(r.message(), "seq: must be >= 1, got 0");
  }
  // A resent rejection is answered the same, not re-evaluated.
  const CommandReply again = ca.Send(rejected[0].first, cases[0].command);
  EXPECT_TRUE(again.duplicate());
  EXPECT_EQ(again.code(), rejected[0].second.code());
  EXPECT_EQ(again.message(), rejected[0].second.message());
  EXPECT_EQ(again.applied_step(), 10);

  const SessionStats stats = StatsOf(*stub_, a);
  EXPECT_EQ(stats.commands_rejected(), static_cast<int64_t>(cases.size()));
  EXPECT_EQ(stats.commands_applied(), 2);
  EXPECT_EQ(stats.commands_duplicate(), 1);

  const InspectReply ia = InspectAt(*stub_, a, 10), ib = InspectAt(*stub_, b, 10);
  EXPECT_TRUE(BitIdentical(ia.control_positions(), ib.control_positions()));
  // The same future: the next valid commands get the same ids and steps.
  const CommandReply fa = ca.Send(seq, ForceCommand(1.5, 1.5, 3, 0, 1e4, 0));
  const CommandReply fb = cb.Send(3, ForceCommand(1.5, 1.5, 3, 0, 1e4, 0));
  EXPECT_EQ(fa.load_id(), fb.load_id());
  EXPECT_EQ(fa.applied_step(), fb.applied_step());
  ASSERT_EQ(ca.Send(seq + 1, StepCommand(40)).code(), 0);
  ASSERT_EQ(cb.Send(4, StepCommand(40)).code(), 0);
  const InspectReply ea = InspectAt(*stub_, a, 50), eb = InspectAt(*stub_, b, 50);
  EXPECT_EQ(ea.step(), 50);
  EXPECT_TRUE(BitIdentical(ea.control_positions(), eb.control_positions()));
  EXPECT_TRUE(BitIdentical(ea.surface_positions(), eb.surface_positions()));
  EXPECT_FALSE(BitIdentical(ea.control_positions(), ia.control_positions()));  // it moved
}

TEST_F(LiveTest, AResendAfterADroppedConnectionIsAppliedExactlyOnce) {
  // Paused sessions: every command below applies at step 0, whatever the
  // timing, so a reference session can get the same history.
  const Session s = Create("block3", 1, true);
  const Session ref = Create("block3", 1, true);
  Command gravity;
  gravity.mutable_set_gravity()->set_y(-3);
  Command fix;
  fix.mutable_fix_region()->mutable_sphere()->mutable_center()->set_x(3);
  fix.mutable_fix_region()->mutable_sphere()->mutable_center()->set_z(3);
  fix.mutable_fix_region()->mutable_sphere()->set_radius(0.2);
  std::vector<Command> script = {ForceCommand(1.5, 1.5, 3, 1e4, 0, 0), gravity,
                                 ForceCommand(0.5, 1.5, 3, 0, 1e4, 0), fix,
                                 ForceCommand(2.5, 1.5, 3, 0, 0, -1e4),
                                 ForceCommand(1.5, 0.5, 2, 0, 5e3, 0)};
  std::vector<CommandReply> first(script.size());
  {
    CommandStream c(*stub_, s, "resender");
    for (size_t i = 0; i < script.size(); ++i) ASSERT_TRUE(c.Write(i + 1, script[i]));
    // Read only half the answers, then the connection "breaks".
    for (size_t i = 0; i < 3; ++i) ASSERT_TRUE(c.Read(&first[i]));
    c.Cancel();
  }
  // The client does not know what happened to 4..6: it resends everything.
  CommandStream c(*stub_, s, "resender");
  std::vector<CommandReply> second;
  for (size_t i = 0; i < script.size(); ++i) second.push_back(c.Send(i + 1, script[i]));
  for (size_t i = 0; i < script.size(); ++i) {
    EXPECT_EQ(second[i].code(), 0) << i << ": " << second[i].message();
    EXPECT_EQ(second[i].applied_step(), 0) << i;
  }
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(second[i].duplicate()) << i;
    EXPECT_EQ(second[i].load_id(), first[i].load_id()) << i;
  }
  // Ids are handed out once per applied command: distinct and increasing.
  EXPECT_LT(second[0].load_id(), second[2].load_id());
  EXPECT_LT(second[2].load_id(), second[3].constraint_id());
  EXPECT_LT(second[3].constraint_id(), second[4].load_id());
  EXPECT_LT(second[4].load_id(), second[5].load_id());
  // And resending once more changes nothing either.
  for (size_t i = 0; i < script.size(); ++i) {
    const CommandReply third = c.Send(i + 1, script[i]);
    EXPECT_TRUE(third.duplicate());
    EXPECT_EQ(third.applied_step(), second[i].applied_step());
    EXPECT_EQ(third.load_id(), second[i].load_id());
    EXPECT_EQ(third.constraint_id(), second[i].constraint_id());
  }
  const SessionStats stats = StatsOf(*stub_, s);
  EXPECT_EQ(stats.commands_applied(), 6);
  EXPECT_GE(stats.commands_duplicate(), 9);
  ASSERT_EQ(c.Send(7, StepCommand(15)).code(), 0);

  // The reference session gets each command once.
  CommandStream cr(*stub_, ref, "reference");
  for (size_t i = 0; i < script.size(); ++i) {
    const CommandReply r = cr.Send(i + 1, script[i]);
    EXPECT_EQ(r.applied_step(), 0) << i;
    EXPECT_EQ(r.load_id(), second[i].load_id()) << i;
    EXPECT_EQ(r.constraint_id(), second[i].constraint_id()) << i;
  }
  ASSERT_EQ(cr.Send(7, StepCommand(15)).code(), 0);
  const InspectReply a = InspectAt(*stub_, s, 15), b = InspectAt(*stub_, ref, 15);
  EXPECT_EQ(a.step(), 15);
  EXPECT_TRUE(BitIdentical(a.control_positions(), b.control_positions()));
  EXPECT_TRUE(BitIdentical(a.surface_positions(), b.surface_positions()));
  // A seq below the last one whose answer is not kept: OUT_OF_RANGE.
  ServerOptions small = Options();
  small.loop.core.answer_cache = 2;
  Start(small);
  const Session t = Create("block3", 1, true);
  CommandStream ct(*stub_, t, "forgetful");
  for (uint64_t i = 1; i <= 4; ++i) ASSERT_EQ(ct.Send(i, StepCommand(1)).code(), 0);
  const CommandReply old = ct.Send(1, StepCommand(1));
  EXPECT_EQ(old.code(), 11);
  EXPECT_EQ(old.applied_step(), -1);
  EXPECT_THAT(old.message(), HasSubstr("keeps the last 2 per client"));
  EXPECT_TRUE(ct.Send(4, StepCommand(1)).duplicate());
}

TEST_F(LiveTest, WrongOrMissingTokensAreRefusedOnEveryCall) {
  const Session s = Create("block3", 1, true);
  Session wrong = s;
  wrong.set_token(std::string(32, '0'));
  Session missing = s;
  missing.clear_token();
  for (const Session& bad : {wrong, missing}) {
    SCOPED_TRACE(bad.token().empty() ? "missing" : "wrong");
    {
      grpc::ClientContext context;
      context.set_deadline(Deadline());
      SessionStats stats;
      EXPECT_EQ(stub_->GetStats(&context, RefOf(bad), &stats).error_code(),
                grpc::StatusCode::PERMISSION_DENIED);
    }
    {
      grpc::Status status;
      InspectAt(*stub_, bad, 0, true, true, &status);
      EXPECT_EQ(status.error_code(), grpc::StatusCode::PERMISSION_DENIED);
    }
    {
      WatchRequest r;
      *r.mutable_session() = RefOf(bad);
      const grpc::Status status = RefusedWatch(r);
      EXPECT_EQ(status.error_code(), grpc::StatusCode::PERMISSION_DENIED);
      EXPECT_THAT(status.error_message(), HasSubstr("token"));
    }
    {
      CommandStream c(*stub_, bad, "intruder");
      ASSERT_TRUE(c.Write(1, StepCommand(5)));
      CommandReply r;
      EXPECT_FALSE(c.Read(&r));
      EXPECT_EQ(c.Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);
    }
  }
  // A stream opened with the right token cannot switch to a wrong one.
  CommandStream c(*stub_, s, "switcher");
  ASSERT_EQ(c.Send(1, StepCommand(1)).code(), 0);
  CommandRequest r;
  *r.mutable_session() = RefOf(wrong);
  r.set_client_id("switcher");
  r.set_seq(2);
  *r.mutable_command() = StepCommand(1);
  ASSERT_TRUE(c.WriteRaw(r));
  CommandReply reply;
  EXPECT_FALSE(c.Read(&reply));
  EXPECT_EQ(c.Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);
  // Nothing was applied by the refused calls.
  EXPECT_EQ(StatsOf(*stub_, s).commands_applied(), 1);
}

TEST_F(LiveTest, CommandsBeyondTheRateLimitAreRefusedAndCanBeResent) {
  ServerOptions o = Options();
  o.loop.commands_per_second = 5;
  Start(o);
  const Session s = Create("block3", 1, true);
  CommandStream c(*stub_, s, "hasty");
  int ok = 0, limited = 0;
  uint64_t first_limited = 0;
  // All 20 written at once (well within one second, however busy the
  // machine), then the answers read.
  for (uint64_t i = 1; i <= 20; ++i) ASSERT_TRUE(c.Write(i, StepCommand(1)));
  for (uint64_t i = 1; i <= 20; ++i) {
    CommandReply r;
    ASSERT_TRUE(c.Read(&r));
    if (r.code() == 0) ++ok;
    if (r.code() == 8) {
      ++limited;
      // (Refusals are answered at once, applied commands after the loop:
      // answers arrive out of seq order.)
      if (first_limited == 0 || r.seq() < first_limited) first_limited = r.seq();
      EXPECT_EQ(r.applied_step(), -1);
      EXPECT_THAT(r.message(), HasSubstr("--max_commands_per_second"));
    }
  }
  EXPECT_GE(ok, 5);
  EXPECT_GE(limited, 10);
  EXPECT_EQ(StatsOf(*stub_, s).commands_rate_limited(), limited);
  EXPECT_EQ(StatsOf(*stub_, s).commands_applied(), ok);
  // A refused command was not consumed: the same seq is applied later. And
  // order is kept: while seq 6 waits for its resend, a later seq is
  // refused too (so a pipelining client's resends apply in seq order).
  EXPECT_EQ(first_limited, 6u);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  const CommandReply ahead = c.Send(21, StepCommand(1));
  EXPECT_EQ(ahead.code(), 8) << ahead.message();
  const CommandReply later = c.Send(6, StepCommand(1));
  EXPECT_EQ(later.code(), 0) << later.message();
  EXPECT_FALSE(later.duplicate());
  EXPECT_EQ(c.Send(7, StepCommand(1)).code(), 0);
}

TEST_F(LiveTest, StatsReportStepTimesPhasesAndCounts) {
  const Session s = Create("block3", 1, true);
  CommandStream c(*stub_, s, "stats");
  ASSERT_EQ(c.Send(1, StepCommand(30)).code(), 0);
  ASSERT_EQ(c.Send(2, StepCommand(0)).code(), 3);
  InspectAt(*stub_, s, 30, false, false);
  const SessionStats st = StatsOf(*stub_, s);
  EXPECT_EQ(st.step(), 30);
  EXPECT_TRUE(st.paused());
  EXPECT_DOUBLE_EQ(st.time_step(), 1e-3);
  EXPECT_NEAR(st.time(), 0.030, 1e-12);
  EXPECT_EQ(st.steps_measured(), 30);
  EXPECT_GT(st.step_ms_median(), 0);
  EXPECT_GE(st.step_ms_p99(), st.step_ms_median());
  EXPECT_EQ(st.commands_applied(), 1);
  EXPECT_EQ(st.commands_rejected(), 1);
  EXPECT_GE(st.overruns(), 0);
  std::vector<std::string> names;
  for (const PhaseTime& p : st.phases()) {
    names.push_back(p.name());
    EXPECT_GE(p.median_ms(), 0) << p.name();
  }
  // block3 (corotational per control cell, central difference): the
  // stiffness and the solve run; no deformation measure (the local frame's).
  EXPECT_THAT(names, ::testing::IsSupersetOf({"stiffness", "solve"}));
  EXPECT_THAT(names, ::testing::Not(::testing::Contains("measure")));
  EXPECT_EQ(st.watchers(), 0);
  EXPECT_EQ(st.journal_records(), 0);  // no data dir
}

// A topology edit builds its new solid off the loop: the running session
// keeps stepping meanwhile, the edit applies at a later step boundary with a
// short hold, and commands sent behind it (by its client and by another)
// wait and apply after it, in order.
TEST_F(LiveTest, ATopologyEditBuildsOffTheLoopWhileTheSolidStepsAndLaterCommandsWait) {
  const Session s = Create("block3", 2, /*paused=*/false);
  CommandStream a(*stub_, s, "editor"), b(*stub_, s, "other");
  const int64_t before = StatsOf(*stub_, s).step();
  Command extrude, gravity, force, undo;
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(
      "edit { extrude_faces { near { x: 1.5 y: 1.5 z: 3 } distance: 0.5 } }", &extrude));
  gravity.mutable_set_gravity()->set_z(-9.81);
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(
      "add_point_force { position { x: 1.5 y: 1.5 z: 3.3 } force { x: 10 } }", &force));
  undo.mutable_undo();
  ASSERT_TRUE(a.Write(1, extrude));
  ASSERT_TRUE(a.Write(2, gravity));
  CommandReply r1, r2;
  ASSERT_TRUE(a.Read(&r1));
  ASSERT_TRUE(a.Read(&r2));
  ASSERT_EQ(r1.code(), 0) << r1.message();
  ASSERT_EQ(r2.code(), 0) << r2.message();
  EXPECT_EQ(r1.edit().control_cells_after(), 28);
  EXPECT_GT(r1.edit().build_ms(), 0);
  EXPECT_GT(r1.applied_step(), before);             // the solid stepped while it built
  EXPECT_GE(r2.applied_step(), r1.applied_step());  // and the next command came after
  const CommandReply r3 = b.Send(1, force);
  EXPECT_EQ(r3.code(), 0) << r3.message();  // the force's point is in the new column
  // Undo of the edit comes back to 27 cells. (Undo is each person's own:
  // the editor's gravity, then its extrude; the other client's force,
  // whose point was in the new column, has no place left and goes.)
  ASSERT_EQ(a.Send(3, undo).code(), 0);
  const CommandReply u2 = a.Send(4, undo);
  ASSERT_EQ(u2.code(), 0) << u2.message();
  EXPECT_EQ(u2.history().what(), "extrude 1 face");
  EXPECT_EQ(u2.history().undo_depth(), 0);
  InspectRequest ir;
  *ir.mutable_session() = RefOf(s);
  ir.set_control_mesh(true);
  InspectReply info;
  ASSERT_TRUE(Inspect(ir, &info).ok());
  EXPECT_EQ(info.control_mesh().cells(), 27);
}

// A drag or curve lasts as long as the command stream that started it: when
// the stream ends (finished or broken), the server releases it with a
// journaled remove_load of its own; other loads stay.
TEST_F(LiveTest, DragsAndCurvesAreReleasedWhenTheirCommandStreamEnds) {
  const Session s = Create("block3", 1, /*paused=*/false);
  Command drag, curve, force;
  ASSERT_TRUE(ParseCommands({
      {&drag, "drag { material_point { x: 1.5 y: 1.5 z: 3 } target { x: 1.5 y: 1.5 z: 3.3 } "
              "stiffness: 1e4 }"},
      {&curve, "curve { material_points { x: 0 y: 0 z: 3 } material_points { x: 3 y: 0 z: 3 } "
               "targets { x: 0 y: 0 z: 3.1 } targets { x: 3 y: 0 z: 3.1 } stiffness: 1e4 }"},
      {&force, "add_point_force { position { x: 1.5 y: 1.5 z: 3 } force { x: 10 } }"}}));
  int64_t drag_id = 0, curve_id = 0, force_id = 0;
  // Waits (bounded) until the session has applied `n` commands.
  auto applied = [&](int64_t n) {
    int64_t got = 0;
    for (int i = 0; i < 500 && got < n; ++i) {
      got = StatsOf(*stub_, s).commands_applied();
      if (got < n) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return got;
  };
  {
    CommandStream a(*stub_, s, "hand");
    drag_id = a.Send(1, drag).load_id();
    force_id = a.Send(2, force).load_id();
    ASSERT_GT(drag_id, 0);
    ASSERT_GT(force_id, 0);
    ASSERT_TRUE(a.Finish().ok());
  }
  EXPECT_EQ(applied(3), 3);  // drag, force, the server's release of the drag
  {
    CommandStream b(*stub_, s, "broken");
    curve_id = b.Send(1, curve).load_id();
    ASSERT_GT(curve_id, 0);
    b.Cancel();  // a broken connection
  }
  EXPECT_EQ(applied(5), 5);  // the curve and its release
  CommandStream c(*stub_, s, "check");
  Command remove;
  remove.mutable_remove_load()->set_load_id(drag_id);
  EXPECT_EQ(c.Send(1, remove).code(), static_cast<int>(grpc::StatusCode::NOT_FOUND));
  remove.mutable_remove_load()->set_load_id(curve_id);
  EXPECT_EQ(c.Send(2, remove).code(), static_cast<int>(grpc::StatusCode::NOT_FOUND));
  remove.mutable_remove_load()->set_load_id(force_id);
  EXPECT_EQ(c.Send(3, remove).code(), 0);  // a force outlives its stream
  // And nobody may pose as the server.
  CommandStream d(*stub_, s, "server:release");
  const CommandReply r = d.Send(1, force);
  EXPECT_EQ(r.code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_THAT(r.message(), ::testing::HasSubstr("starts with \"server:\""));
}

// Inspect with loads: what every client placed, with its owner, from the
// simulation thread between two steps.
TEST_F(LiveTest, InspectListsTheLoadsAndConstraintsOfEveryClient) {
  const Session s = Create("block3", 1, /*paused=*/true);
  Command force, drag, fix;
  ASSERT_TRUE(ParseCommands({
      {&force, "add_point_force { position { x: 1.5 y: 1.5 z: 2 } force { z: -5 } }"},
      {&drag, "drag { material_point { x: 1.5 y: 1.5 z: 3 } target { x: 1.5 y: 1.5 z: 3.3 } "
              "stiffness: 1e4 }"},
      {&fix, "fix_region { box { min { x: 2.99 y: -1 z: -1 } max { x: 3.01 y: 4 z: 4 } } }"}}));
  CommandStream a(*stub_, s, "viewer-a"), b(*stub_, s, "viewer-b");
  const int64_t force_id = a.Send(1, force).load_id();
  const int64_t drag_id = b.Send(1, drag).load_id();
  const int64_t fix_id = b.Send(2, fix).constraint_id();
  ASSERT_TRUE(force_id > 0 && drag_id > 0 && fix_id > 0);
  InspectRequest ir;
  *ir.mutable_session() = RefOf(s);
  ir.set_loads(true);
  InspectReply info;
  ASSERT_TRUE(Inspect(ir, &info).ok());
  ASSERT_EQ(info.loads_size(), 2);
  EXPECT_EQ(info.loads(0).id(), force_id);
  EXPECT_EQ(info.loads(0).kind(), "point_force");
  EXPECT_EQ(info.loads(0).client_id(), "viewer-a");
  EXPECT_EQ(info.loads(1).id(), drag_id);
  EXPECT_EQ(info.loads(1).kind(), "drag");
  EXPECT_EQ(info.loads(1).client_id(), "viewer-b");
  EXPECT_DOUBLE_EQ(info.loads(1).target().z(), 3.3);
  ASSERT_EQ(info.constraints_size(), 2);  // the scene's bottom, then viewer-b's side
  EXPECT_EQ(info.constraints(0).client_id(), "");
  EXPECT_EQ(info.constraints(1).id(), fix_id);
  EXPECT_EQ(info.constraints(1).client_id(), "viewer-b");
  EXPECT_EQ(info.constraints(1).control_points(), 16);
  // Without loads: none listed.
  ir.set_loads(false);
  InspectReply plain;
  ASSERT_TRUE(Inspect(ir, &plain).ok());
  EXPECT_EQ(plain.loads_size() + plain.constraints_size(), 0);
  EXPECT_FALSE(plain.has_gravity());
}

TEST_F(LiveTest, StepsSlowerThanRealTimeAreCountedAsOverrunsAndNeverBuildDebt) {
  // h = 10 microseconds: no machine steps this block (two levels, the
  // local-frame model: about 0.5 ms a step) in real time. The loop catches
  // up at most 25 ms of debt (kCatchUp); 200 such steps take far longer
  // than that beyond their 2 ms of simulated time, so it must count overruns
  // and re-anchor its clock rather than owe ever more steps (counts only; no
  // wall time is asserted).
  const Session s = CreateText(R"(
    name: "tiny_step"
    mesh { block { nx: 3 ny: 3 nz: 3 } }
    subdivision { levels: 2 }
    materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 } }
    constraints { fixed { box { min { z: -0.01 } max { x: 3 y: 3 z: 0.01 } } } }
    solver { time_step: 1e-5 }
  )", /*paused=*/true);
  CommandStream c(*stub_, s, "overrun");
  ASSERT_EQ(c.Send(1, StepCommand(200)).code(), 0);
  InspectAt(*stub_, s, 200, false, false);
  const SessionStats st = StatsOf(*stub_, s);
  EXPECT_EQ(st.step(), 200);
  EXPECT_GT(st.overruns(), 0);
  EXPECT_GT(st.steps_dropped(), 0);
  // Each overrun drops the lag of that one step: the lag reported is the
  // last step's, not an accumulated debt.
  EXPECT_LE(st.steps_behind(), st.steps_dropped());
}

TEST_F(LiveTest, ClosingASessionFinishesItsStreams) {
  const Session s = Create("block3", 1, false);
  grpc::ClientContext wc;
  auto reader = WatchOf(s, &wc);
  ASSERT_TRUE(ReadsAFrame(*reader));
  CommandStream c(*stub_, s, "closer");
  ASSERT_EQ(c.Send(1, StepCommand(3)).code(), 0);
  {
    grpc::ClientContext context;
    google::protobuf::Empty e;
    ASSERT_TRUE(stub_->CloseSession(&context, RefOf(s), &e).ok());
  }
  ExpectStreamsEndUnavailable(*reader, c, "was closed");
}

}  // namespace
}  // namespace dynsolid::server
