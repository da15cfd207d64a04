// Watch over loopback gRPC against an in-process server: keyframes and
// quantized deltas reconstruct the server's positions, early frames after
// commands (to the commanding client's watchers), delta sizes, slow
// watchers, and refused watch requests.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "dynsolid/service.grpc.pb.h"
#include "live_client.h"
#include "live_fixture.h"
#include "server/server.h"
#include "clients/lib/surface.h"
#include "server/surface_codec.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;

TEST_F(LiveTest, KeyframeAndDeltasReconstructTheServerPositionsWithinTheStatedBound) {
  const Session s = Create("block3", 1, /*paused=*/true);
  EXPECT_DOUBLE_EQ(s.time_step(), 1e-3);
  grpc::ClientContext wc;
  wc.set_deadline(Deadline(120));
  WatchRequest wr;
  *wr.mutable_session() = RefOf(s);
  wr.set_displacement(true);
  auto reader = stub_->Watch(&wc, wr);
  client::SurfaceDecoder decoder;
  std::vector<Frame> frames;
  ASSERT_TRUE(ReadUntilStep(*reader, decoder, 0, &frames));
  ASSERT_TRUE(frames[0].has_keyframe());
  const int vertices = frames[0].keyframe().vertex_count();
  EXPECT_EQ(vertices, 6 * 6 * 6 + 2);  // the boundary of a 6^3 grid of cells
  EXPECT_EQ(frames[0].keyframe().quads_size(), 4 * 6 * 36);

  CommandStream commands(*stub_, s, "reconstruct");
  // Pull the top sideways: the block sways.
  CommandReply r = commands.Send(1, ForceCommand(1.5, 1.5, 3, 3e4, 0, 0));
  ASSERT_EQ(r.code(), 0) << r.message();
  EXPECT_EQ(r.applied_step(), 0);
  int moved_total = 0;
  for (int k = 1; k <= 6; ++k) {
    r = commands.Send(1 + k, StepCommand(25));
    ASSERT_EQ(r.code(), 0) << r.message();
    const InspectReply server = InspectAt(*stub_, s, 25 * k);
    ASSERT_EQ(server.step(), 25 * k);
    ASSERT_TRUE(server.paused());
    ASSERT_TRUE(ReadUntilStep(*reader, decoder, 25 * k, &frames)) << "k = " << k;
    const double worst = WorstRatio(decoder, server);
    EXPECT_LE(worst, 1.0 + 1e-9) << "at step " << 25 * k;
    EXPECT_GT(worst, 0.0);  // quantized, not exact
    // And the block did move, by more than the bound.
    double largest_motion = 0;
    const std::vector<double> now = decoder.surface().positions;
    (void)now;
    for (const Frame& f : frames) {
      if (f.has_delta()) moved_total += f.delta().moved();
    }
    frames.clear();
    (void)largest_motion;
  }
  EXPECT_GT(moved_total, vertices) << "deltas listed too few moved vertices";
  EXPECT_EQ(static_cast<int>(decoder.surface().displacement.size()), vertices);
  wc.TryCancel();
}

// A watcher that asks for one frame a second still sees a command's effect
// at once: the frame after the command's step goes out then, not a second
// later (at most max_watch_hz; SessionLoop::frame_for_command_).
TEST_F(LiveTest, AFrameFollowsAnAppliedCommandWithinAStepWhateverTheWatchRate) {
  const Session s = Create("block3", 1, /*paused=*/false);
  grpc::ClientContext wc;
  wc.set_deadline(Deadline(120));
  WatchRequest wr;
  *wr.mutable_session() = RefOf(s);
  wr.set_rate_hz(1);
  auto reader = stub_->Watch(&wc, wr);
  client::SurfaceDecoder decoder;
  Frame first;
  ASSERT_TRUE(reader->Read(&first));
  ASSERT_TRUE(decoder.Apply(first).ok());
  CommandStream commands(*stub_, s, "frames");
  for (uint64_t seq = 1; seq <= 3; ++seq) {
    const CommandReply r = commands.Send(seq, ForceCommand(1.5, 1.5, 3, 1e3 * seq, 0, 0));
    ASSERT_EQ(r.code(), 0) << r.message();
    // The first frame at or after the command's step: at most a few steps
    // later (1 Hz frames would be about 1000 steps apart).
    Frame f;
    do {
      ASSERT_TRUE(reader->Read(&f));
      ASSERT_TRUE(decoder.Apply(f).ok());
    } while (f.step() < r.applied_step());
    EXPECT_LE(f.step(), r.applied_step() + 20) << "seq " << seq;
  }
  wc.TryCancel();
}

// With many clients on one session, each watcher that names its client
// (WatchRequest.client_id) gets the early frame of its own client's
// commands only; a watcher that names none gets every client's. All three
// watch at 0.1 Hz (10 s between the frames every watcher gets).
TEST_F(LiveTest, AnEarlyFrameGoesToTheCommandingClientsWatchersAndToThoseThatNameNone) {
  const Session s = Create("block3", 1, /*paused=*/false);
  struct Watch {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReader<Frame>> reader;
    client::SurfaceDecoder decoder;
    int64_t id = -1;
  };
  auto open = [&](Watch& w, const std::string& client) {
    w.context.set_deadline(Deadline(120));
    WatchRequest wr;
    *wr.mutable_session() = RefOf(s);
    wr.set_rate_hz(0.1);
    wr.set_client_id(client);
    w.reader = stub_->Watch(&w.context, wr);
    Frame first;
    ASSERT_TRUE(w.reader->Read(&first));
    ASSERT_TRUE(w.decoder.Apply(first).ok());
    w.id = first.watcher_id();
  };
  Watch mine, theirs, everyone;
  open(mine, "sculptor-a");
  open(theirs, "sculptor-b");
  open(everyone, "");
  CommandStream commands(*stub_, s, "sculptor-a");
  for (uint64_t seq = 1; seq <= 3; ++seq) {
    const CommandReply r = commands.Send(seq, ForceCommand(1.5, 1.5, 3, 1e3 * seq, 0, 0));
    ASSERT_EQ(r.code(), 0) << r.message();
    for (Watch* w : {&mine, &everyone}) {
      Frame f;
      do {
        ASSERT_TRUE(w->reader->Read(&f));
        ASSERT_TRUE(w->decoder.Apply(f).ok());
      } while (f.step() < r.applied_step());
      EXPECT_LE(f.step(), r.applied_step() + 20) << "seq " << seq << ", watcher " << w->id;
    }
  }
  // The other client's watcher had none of them early: fewer frames than
  // the commanding client's (frames every watcher gets count in both).
  const SessionStats st = StatsOf(*stub_, s);
  int64_t sent_mine = -1, sent_theirs = -1, sent_everyone = -1;
  for (const WatcherStats& w : st.watcher_details()) {
    if (w.watcher_id() == mine.id) sent_mine = w.frames_sent();
    if (w.watcher_id() == theirs.id) sent_theirs = w.frames_sent();
    if (w.watcher_id() == everyone.id) sent_everyone = w.frames_sent();
  }
  EXPECT_GE(sent_mine, 2);
  EXPECT_GE(sent_everyone, 2);
  EXPECT_GE(sent_theirs, 1);
  EXPECT_LT(sent_theirs, sent_mine);
  EXPECT_LT(sent_theirs, sent_everyone);
  for (Watch* w : {&mine, &theirs, &everyone}) w->context.TryCancel();
}

TEST_F(LiveTest, AWatchRequestsClientIdOfMoreThan64CharactersIsRefused) {
  const Session s = Create("block3", 1, /*paused=*/true);
  WatchRequest wr;
  *wr.mutable_session() = RefOf(s);
  wr.set_client_id(std::string(65, 'x'));
  const grpc::Status st = RefusedWatch(wr);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(st.error_message(), "client_id: must have at most 64 characters, got 65");
}

TEST_F(LiveTest, Block3DeltaFramesAreAtMostAQuarterOfRawFloat32Frames) {
  // The default scene at its two levels, pulled at the top corner: every
  // delta frame of a 60 Hz watcher against 12 bytes per vertex.
  const Session s = Create("block3", 2, /*paused=*/true);
  grpc::ClientContext wc;
  wc.set_deadline(Deadline(120));
  WatchRequest wr;
  *wr.mutable_session() = RefOf(s);
  auto reader = stub_->Watch(&wc, wr);
  client::SurfaceDecoder decoder;
  std::vector<Frame> frames;
  ASSERT_TRUE(ReadUntilStep(*reader, decoder, 0, &frames));
  const int vertices = frames[0].keyframe().vertex_count();
  EXPECT_EQ(vertices, 6 * 12 * 12 + 2);
  CommandStream c(*stub_, s, "pull");
  ASSERT_EQ(c.Send(1, ForceCommand(3, 3, 3, 2e4, 1e4, 0)).code(), 0);
  // 300 steps in chunks of 16 (1/60 s at the scene's 1 ms step: what a 60 Hz
  // watcher of a real-time session sees), each chunk's last frame read
  // before the next chunk: every delta spans at most 16 steps, whatever the
  // load on the machine (a burst of 300 steps would let a starved encoder
  // send few deltas over many steps each, and the ratio would measure the
  // scheduler).
  frames.clear();
  constexpr int kChunk = 16, kSteps = 300;
  for (int done = 0, seq = 2; done < kSteps; ++seq) {
    const int n = std::min(kChunk, kSteps - done);
    ASSERT_EQ(c.Send(seq, StepCommand(n)).code(), 0);
    done += n;
    ASSERT_TRUE(ReadUntilStep(*reader, decoder, done, &frames));
  }
  const InspectReply server = InspectAt(*stub_, s, kSteps);
  EXPECT_LE(WorstRatio(decoder, server), 1.0 + 1e-9);
  size_t delta_bytes = 0, deltas = 0, largest = 0;
  int64_t moved = 0;
  for (const Frame& f : frames) {
    if (!f.has_delta()) continue;
    ++deltas;
    delta_bytes += f.ByteSizeLong();
    largest = std::max(largest, f.ByteSizeLong());
    moved += f.delta().moved();
  }
  const double raw = 12.0 * vertices;
  ASSERT_GT(deltas, 3u);
  EXPECT_GT(moved, 0);
  const double mean_ratio = delta_bytes / (deltas * raw);
  RecordProperty("delta_frames", static_cast<int>(deltas));
  RecordProperty("mean_delta_over_raw_percent", static_cast<int>(100 * mean_ratio));
  RecordProperty("largest_delta_over_raw_percent", static_cast<int>(100 * largest / raw));
  std::printf("block3: %zu delta frames, mean %.1f %% and largest %.1f %% of a raw float32 "
              "frame (%.0f bytes), %.0f moved vertices per delta\n",
              deltas, 100 * mean_ratio, 100 * largest / raw, raw,
              static_cast<double>(moved) / deltas);
  EXPECT_LE(mean_ratio, 0.25);
  wc.TryCancel();
}

TEST_F(LiveTest, ASlowWatcherNeitherSlowsTheLoopNorOtherWatchersAndResumesConsistently) {
  ServerOptions o = Options();
  o.loop.max_watch_hz = 1000;
  Start(o);
  const Session s = CreateText(SpinningSceneText(), /*paused=*/true);

  // The stalled watcher's channel has a small receive window, so its
  // server-side writes block once it stops reading.
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetInt("grpc.http2.lookahead_bytes", 8192);
  auto slow_channel = grpc::CreateCustomChannel(server_->address(),
                                                grpc::InsecureChannelCredentials(), args);
  auto slow_stub = Sessions::NewStub(slow_channel);
  WatchRequest wr;
  *wr.mutable_session() = RefOf(s);
  wr.set_rate_hz(1000);
  wr.set_displacement(true);
  wr.set_strain(true);
  wr.set_stiffness(true);
  grpc::ClientContext slow_context, fast_context;
  slow_context.set_deadline(Deadline(120));
  fast_context.set_deadline(Deadline(120));
  auto slow = slow_stub->Watch(&slow_context, wr);
  auto fast = stub_->Watch(&fast_context, wr);

  // The fast watcher reads everything on its own thread.
  absl::Mutex mu;
  client::SurfaceDecoder fast_decoder;
  int64_t fast_frames = 0, fast_last_step = -1;
  bool fast_ok = true;
  std::thread fast_reader([&] {
    Frame f;
    while (fast->Read(&f)) {
      absl::MutexLock lock(&mu);
      if (!fast_decoder.Apply(f).ok() || f.step() < fast_last_step) fast_ok = false;
      ++fast_frames;
      fast_last_step = f.step();
    }
  });

  CommandStream commands(*stub_, s, "slow-watch");
  ASSERT_EQ(commands.Send(1, StepCommand(1'000'000)).code(), 0);  // spin on

  // Wait (by counts) until the slow watcher's write is stuck and it skips.
  SessionStats st;
  WatcherStats slow_stats;
  for (int i = 0; i < 600; ++i) {
    st = StatsOf(*stub_, s);
    for (const WatcherStats& w : st.watcher_details()) {
      if (w.watcher_id() == 1) slow_stats = w;
    }
    if (slow_stats.write_pending() && slow_stats.frames_skipped() > 10) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(slow_stats.write_pending()) << "the slow watcher never blocked";
  ASSERT_GT(slow_stats.frames_skipped(), 10);

  // While it does not read, the loop keeps stepping (1500 more steps, by
  // count) and the fast watcher keeps getting frames that follow the
  // session step for step.
  const int64_t step0 = st.step();
  int64_t fast0;
  {
    absl::MutexLock lock(&mu);
    fast0 = fast_frames;
  }
  const InspectReply later = InspectAt(*stub_, s, step0 + 1500, false, false);
  EXPECT_GE(later.step(), step0 + 1500);
  for (int i = 0; i < 600; ++i) {
    absl::MutexLock lock(&mu);
    if (fast_last_step >= step0 + 1500) break;
    mu.Unlock();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    mu.Lock();
  }
  st = StatsOf(*stub_, s);
  for (const WatcherStats& w : st.watcher_details()) {
    if (w.watcher_id() == 1) slow_stats = w;
  }
  {
    absl::MutexLock lock(&mu);
    EXPECT_TRUE(fast_ok);
    EXPECT_GE(fast_last_step, step0 + 1500) << "the fast watcher fell behind the loop";
    // (Streaming threads run under SCHED_IDLE: on a machine busy with other
    // work they get little CPU, so the count is only required to grow.)
    EXPECT_GT(fast_frames - fast0, 5) << "the fast watcher got too few frames";
  }
  // The slow watcher never queues: every frame published since it joined
  // was sent to it once, skipped (replaced in its one-frame slot), or is
  // still in that slot.
  EXPECT_LE(slow_stats.frames_sent() + slow_stats.frames_skipped(), st.frames_published());
  EXPECT_GE(slow_stats.frames_sent() + slow_stats.frames_skipped() + 1,
            st.frames_published() - 1);  // (the first publication may precede it)
  EXPECT_GT(slow_stats.frames_skipped(), 10);

  // Pause and let the slow watcher read again: everything it gets decodes
  // against what it got before, the resumed frame reports what it skipped,
  // and it ends at the session's positions.
  ASSERT_EQ(commands.Send(2, Command()).code(), 3);  // (an empty command: rejected)
  Command pause;
  pause.mutable_pause();
  const CommandReply paused = commands.Send(3, pause);
  ASSERT_EQ(paused.code(), 0);
  const InspectReply server = InspectAt(*stub_, s, 0);
  ASSERT_TRUE(server.paused());
  client::SurfaceDecoder slow_decoder;
  Frame f;
  int64_t reported_skips = 0;
  while (slow_decoder.step() != server.step()) {
    ASSERT_TRUE(slow->Read(&f));
    ASSERT_TRUE(slow_decoder.Apply(f).ok()) << "frame at step " << f.step();
    reported_skips += f.skipped();
  }
  EXPECT_GT(reported_skips, 10);
  EXPECT_LE(WorstRatio(slow_decoder, server), 1.0 + 1e-9);

  slow_context.TryCancel();
  fast_context.TryCancel();
  fast_reader.join();
}

TEST_F(LiveTest, NonFiniteWatchRatesAndTooManyWatchersAreRefused) {
  ServerOptions o = Options();
  o.loop.max_watchers = 1;
  Start(o);
  const Session s = Create("block3", 1, true);
  {
    WatchRequest r;
    *r.mutable_session() = RefOf(s);
    r.set_rate_hz(std::numeric_limits<double>::quiet_NaN());
    const grpc::Status st = RefusedWatch(r);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(st.error_message(), "rate_hz must be finite, got nan");
  }
  grpc::ClientContext first;
  first.set_deadline(Deadline());
  WatchRequest r;
  *r.mutable_session() = RefOf(s);
  auto one = stub_->Watch(&first, r);
  Frame f;
  ASSERT_TRUE(one->Read(&f));
  EXPECT_TRUE(f.has_keyframe());
  EXPECT_EQ(f.watcher_id(), 1);
  grpc::ClientContext second;
  second.set_deadline(Deadline());
  auto two = stub_->Watch(&second, r);
  EXPECT_FALSE(two->Read(&f));
  const grpc::Status st = two->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(st.error_message(), HasSubstr("maximum of 1 watchers"));
  first.TryCancel();
}

}  // namespace
}  // namespace dynsolid::server
