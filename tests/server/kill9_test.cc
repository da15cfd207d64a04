// kill -9 during a scripted session: the real dynsolid-server binary with
// --data_dir is killed while it steps, restarted on the same directory, and
// the session continues; its positions must equal, bit for bit, those of a
// server that ran the same script without interruption. Also a torn journal
// tail (bytes of a record that was never acknowledged) is dropped.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "google/protobuf/text_format.h"

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "dynsolid/service.grpc.pb.h"
#include "live_client.h"
#include "server_process.h"
#include "temp_dir.h"

namespace dynsolid {
namespace {

using testing::BitIdentical;
using testing::CommandStream;
using testing::Deadline;
using testing::ForceCommand;
using testing::InspectAt;
using testing::ParseCommands;
using testing::ServerProcess;
using testing::StepCommand;
using testing::TempDir;

// dynsolid-server on `data_dir`, a periodic snapshot every `snapshot_every_steps`.
std::vector<std::string> DataFlags(const std::string& data_dir, int snapshot_every_steps = 40) {
  return {"--data_dir=" + data_dir, absl::StrCat("--snapshot_every_steps=", snapshot_every_steps)};
}

Session CreatePaused(Sessions::Stub& stub) {
  Session s;
  const grpc::Status status = testing::CreatePausedBlock3(stub, &s);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return s;
}

// The scripted session: (command, step to wait for before the next one).
std::vector<std::pair<Command, int64_t>> Script() {
  std::vector<std::pair<Command, int64_t>> s;
  s.emplace_back(ForceCommand(1.5, 1.5, 3, 2e4, 0, 0), 0);
  s.emplace_back(StepCommand(60), 60);
  Command fix;
  fix.mutable_fix_region()->mutable_box()->mutable_min()->set_x(2.9);
  fix.mutable_fix_region()->mutable_box()->mutable_max()->set_x(3.1);
  fix.mutable_fix_region()->mutable_box()->mutable_max()->set_y(3);
  fix.mutable_fix_region()->mutable_box()->mutable_max()->set_z(3);
  s.emplace_back(fix, 60);
  Command pressure;
  pressure.mutable_add_pressure()->mutable_region()->mutable_sphere()->mutable_center()->set_z(3);
  pressure.mutable_add_pressure()->mutable_region()->mutable_sphere()->set_radius(1.5);
  pressure.mutable_add_pressure()->set_pascals(2000);
  s.emplace_back(pressure, 60);
  s.emplace_back(StepCommand(60), 120);
  Command paint;
  paint.mutable_paint_material()->mutable_region()->mutable_sphere()->mutable_center()->set_x(1.5);
  paint.mutable_paint_material()->mutable_region()->mutable_sphere()->mutable_center()->set_y(1.5);
  paint.mutable_paint_material()->mutable_region()->mutable_sphere()->mutable_center()->set_z(2);
  paint.mutable_paint_material()->mutable_region()->mutable_sphere()->set_radius(1);
  paint.mutable_paint_material()->mutable_material()->set_young_modulus(3e5);
  // Clay (a material that yields): what the pressure, the gravity and the
  // drag do to it flows into its rest shape, state the restart must bring
  // back bit for bit.
  paint.mutable_paint_material()->mutable_material()->set_preset(Material::CLAY);
  paint.mutable_paint_material()->set_strength(1);
  s.emplace_back(paint, 120);
  Command gravity;
  gravity.mutable_set_gravity()->set_z(-9.81);
  s.emplace_back(gravity, 120);
  // Sculpting: an extrude, a local subdivision taken back by undo, a drag,
  // a bake (its shape stamped into the journaled command by the server).
  for (const char* text :
       {"edit { extrude_faces { near { x: 0.5 y: 1.5 z: 3 } distance: 0.5 layers: 2 } }",
        "edit { subdivide_cells { near { x: 0.5 y: 0.5 z: 0.5 } } }", "undo {}",
        "drag { material_point { x: 0.5 y: 1.5 z: 3.5 } target { x: 0.2 y: 1.5 z: 3.9 } "
        "stiffness: 1e4 }",
        // (the sphere pressure, id 4 after the scene's pin, the force and
        // the fix, released first: a bake keeps no region at rest)
        "remove_load { load_id: 4 }", "edit { bake {} }"}) {
    Command c;
    EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &c)) << text;
    s.emplace_back(c, 120);
  }
  // The server is killed while this runs (after step 150). Long enough
  // that the kill lands inside it on a loaded machine too: with 100 steps
  // the test's own process, slowed by a neighbour, once reached the kill
  // after the run had ended.
  s.emplace_back(StepCommand(1000), 150);
  return s;
}
constexpr int64_t kEnd = 1120;

TEST(Kill9Test, ARestartedServerContinuesBitIdenticallyToAnUninterruptedOne) {
  TempDir dir("dynsolid_kill9");
  const std::string log = dir.path() + "/server.log";
  const auto script = Script();

  // The uninterrupted run.
  std::string ref_control, ref_surface;
  InspectReply ref_end, ref_final;
  {
    ServerProcess server(DataFlags(dir.path() + "/reference"), log);
    ASSERT_FALSE(server.address().empty()) << "the server did not start; see " << log;
    auto stub = server.Stub();
    const Session s = CreatePaused(*stub);
    CommandStream c(*stub, s, "scripted");
    for (size_t i = 0; i < script.size(); ++i) {
      ASSERT_EQ(c.Send(i + 1, script[i].first).code(), 0) << i;
      InspectAt(*stub, s, script[i].second, false, false);
    }
    ref_end = InspectAt(*stub, s, kEnd);
    ASSERT_EQ(ref_end.step(), kEnd);
    ASSERT_EQ(c.Send(script.size() + 1, ForceCommand(0.5, 0.5, 3, 0, -1e4, 0)).code(), 0);
    ASSERT_EQ(c.Send(script.size() + 2, StepCommand(30)).code(), 0);
    ref_final = InspectAt(*stub, s, kEnd + 30);
  }

  // The interrupted run.
  const std::string data = dir.path() + "/killed";
  Session s;
  CommandReply last;
  {
    ServerProcess server(DataFlags(data), log);
    ASSERT_FALSE(server.address().empty());
    auto stub = server.Stub();
    s = CreatePaused(*stub);
    CommandStream c(*stub, s, "scripted");
    for (size_t i = 0; i < script.size(); ++i) {
      last = c.Send(i + 1, script[i].first);
      ASSERT_EQ(last.code(), 0) << i;
      InspectAt(*stub, s, script[i].second, false, false);
    }
    const InspectReply at_kill = InspectAt(*stub, s, 0, false, false);
    EXPECT_LT(at_kill.step(), kEnd) << "the run ended before the kill; nothing was interrupted";
    const int status = server.Signal(SIGKILL);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  }
  // A torn record at the end, as if the kill hit a write: never acknowledged.
  {
    const std::string journal = data + "/sessions/" + s.id() + "/journal";
    const int fd = ::open(journal.c_str(), O_WRONLY | O_APPEND);
    ASSERT_GE(fd, 0);
    const char torn[] = {42, 0, 0, 0, 1, 2};
    ASSERT_EQ(::write(fd, torn, sizeof(torn)), static_cast<ssize_t>(sizeof(torn)));
    ::close(fd);
  }
  {
    ServerProcess server(DataFlags(data), log);
    ASSERT_FALSE(server.address().empty()) << "the server did not restart; see " << log;
    auto stub = server.Stub();
    const InspectReply end = InspectAt(*stub, s, kEnd);
    EXPECT_EQ(end.step(), kEnd);
    EXPECT_TRUE(end.paused());
    EXPECT_TRUE(BitIdentical(end.control_positions(), ref_end.control_positions()));
    EXPECT_TRUE(BitIdentical(end.surface_positions(), ref_end.surface_positions()));
    CommandStream c(*stub, s, "scripted");
    // The last command, resent after the crash: answered, not applied again.
    const CommandReply again = c.Send(script.size(), script.back().first);
    EXPECT_TRUE(again.duplicate());
    EXPECT_EQ(again.applied_step(), last.applied_step());
    ASSERT_EQ(c.Send(script.size() + 1, ForceCommand(0.5, 0.5, 3, 0, -1e4, 0)).code(), 0);
    ASSERT_EQ(c.Send(script.size() + 2, StepCommand(30)).code(), 0);
    const InspectReply final_state = InspectAt(*stub, s, kEnd + 30);
    EXPECT_EQ(final_state.step(), kEnd + 30);
    EXPECT_TRUE(BitIdentical(final_state.control_positions(), ref_final.control_positions()));
    EXPECT_TRUE(BitIdentical(final_state.surface_positions(), ref_final.surface_positions()));
    // The solid did move over the run (the comparison is not vacuous).
    EXPECT_FALSE(BitIdentical(final_state.control_positions(), end.control_positions()));
    grpc::ClientContext context;
    SessionStats stats;
    ASSERT_TRUE(stub->GetStats(&context, testing::RefOf(s), &stats).ok());
    EXPECT_EQ(stats.commands_applied(), static_cast<int64_t>(script.size()) + 2);
  }
  // Recovery restored a periodic snapshot, replayed the journal after it
  // and dropped the torn tail (the server's log says so).
  std::string text;
  {
    const int fd = ::open(log.c_str(), O_RDONLY);
    char buf[4096];
    ssize_t n;
    while ((n = ::read(fd, buf, sizeof(buf))) > 0) text.append(buf, static_cast<size_t>(n));
    ::close(fd);
  }
  EXPECT_THAT(text, ::testing::HasSubstr(absl::StrCat("session ", s.id(), " recovered: snapshot at step")));
  EXPECT_THAT(text, ::testing::HasSubstr("dropped 6 bytes of unacknowledged tail"));
}

// Loads of other clients go ahead of a paint being built (they do not
// wait for its build), and the journal keeps the order they were applied
// in: a server killed afterwards replays it, paint included, to the same
// bits. Nothing is snapshotted after the start, so all of it is replayed.
TEST(Kill9Test, LoadsThatWentAheadOfAPaintReplayInTheOrderTheyWereApplied) {
  TempDir dir("dynsolid_kill9");
  const std::string log = dir.path() + "/server.log";
  const std::string data = dir.path() + "/data";
  Session s;
  InspectReply live;
  {
    ServerProcess server(DataFlags(data, /*snapshot_every_steps=*/1000000), log);
    ASSERT_FALSE(server.address().empty()) << "the server did not start; see " << log;
    auto stub = server.Stub();
    CreateSessionRequest r;
    r.set_builtin_scene("block3");
    r.set_levels_override(2);  // a paint of the whole block builds for 0.1 s and more
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    ASSERT_TRUE(stub->CreateSession(&context, r, &s).ok());
    CommandStream painter(*stub, s, "painter"), pusher(*stub, s, "pusher");
    InspectAt(*stub, s, 5, false, false);
    // Two paints of the whole block in a row: the loop builds one after
    // the other (0.1 s and more each), so that the other client's force
    // surely lands while one of them builds.
    Command paint, paint2, fix;
    ASSERT_TRUE(ParseCommands({
        {&paint,
         "paint_material { region { sphere { center { x: 1.5 y: 1.5 z: 1.5 } radius: 3 } } "
         "material { young_modulus: 3e5 } strength: 1 }"},
        {&paint2,
         "paint_material { region { sphere { center { x: 1.5 y: 1.5 z: 1.5 } radius: 3 } } "
         "material { young_modulus: 2e5 } strength: 1 }"},
        {&fix, "fix_region { box { min { x: 2.9 } max { x: 3.1 y: 3 z: 3 } } }"}}));
    ASSERT_TRUE(painter.Write(1, paint));
    ASSERT_TRUE(painter.Write(2, paint2));
    ASSERT_TRUE(painter.Write(3, ForceCommand(1.5, 1.5, 3, 0, 0, -2e4)));
    // Once the first paint's build is done the loop has both paints (the
    // second is building now, the painter's force waits behind it). Waiting
    // for that, not for a number of steps: on a loaded machine the painter's
    // stream can take longer than a few steps to deliver, and the other
    // client's commands would then rightly go first.
    for (int tries = 0;; ++tries) {
      grpc::ClientContext context;
      context.set_deadline(Deadline());
      SessionStats stats;
      ASSERT_TRUE(stub->GetStats(&context, testing::RefOf(s), &stats).ok());
      if (stats.builds() >= 1) break;
      ASSERT_LT(tries, 6000) << "the first paint was not built within 60 s";
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    const CommandReply pushed = pusher.Send(1, ForceCommand(0.5, 0.5, 3, 1e4, 0, 0));
    const CommandReply fixed = pusher.Send(2, fix);
    CommandReply painted, painted2, forced;
    ASSERT_TRUE(painter.Read(&painted));
    ASSERT_TRUE(painter.Read(&painted2));
    ASSERT_TRUE(painter.Read(&forced));
    for (const CommandReply* reply : {&pushed, &fixed, static_cast<const CommandReply*>(&painted),
                                      static_cast<const CommandReply*>(&painted2),
                                      static_cast<const CommandReply*>(&forced)}) {
      ASSERT_EQ(reply->code(), 0) << reply->message();
    }
    EXPECT_LT(pushed.applied_step(), painted2.applied_step())
        << "another client's force waited for the paints' builds";
    EXPECT_GE(painted2.applied_step(), painted.applied_step());
    EXPECT_GE(forced.applied_step(), painted2.applied_step())
        << "the painter's own force went ahead of its paint";
    EXPECT_GE(fixed.applied_step(), painted2.applied_step())
        << "a constraint (which the build reads) went ahead of the paint";
    Command pause;
    pause.mutable_pause();
    const CommandReply paused = pusher.Send(3, pause);
    ASSERT_EQ(paused.code(), 0) << paused.message();
    live = InspectAt(*stub, s, paused.applied_step());
    ASSERT_EQ(live.step(), paused.applied_step());
    const int status = server.Signal(SIGKILL);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  }
  ServerProcess server(DataFlags(data, /*snapshot_every_steps=*/1000000), log);
  ASSERT_FALSE(server.address().empty()) << "the server did not restart; see " << log;
  auto stub = server.Stub();
  const InspectReply recovered = InspectAt(*stub, s, live.step());
  EXPECT_EQ(recovered.step(), live.step());
  EXPECT_TRUE(recovered.paused());
  EXPECT_TRUE(BitIdentical(recovered.control_positions(), live.control_positions()));
  EXPECT_TRUE(BitIdentical(recovered.surface_positions(), live.surface_positions()));
}

}  // namespace
}  // namespace dynsolid
