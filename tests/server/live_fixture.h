// The fixture of the live-session tests (live_test.cc, watch_live_test.cc):
// an in-process server on a loopback port, sessions made from built-in
// scenes or scene text, and the frame helpers the Watch tests share.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/status/statusor.h"
#include "dynsolid/service.grpc.pb.h"
#include "live_client.h"
#include "server/server.h"
#include "clients/lib/surface.h"
#include "server/surface_codec.h"

namespace dynsolid::server {

// The live client's helpers (live_client.h), unqualified in the live tests.
using namespace ::dynsolid::testing;  // NOLINT(build/namespaces)

// An in-process server on a loopback port (127.0.0.1:0) and a stub to it;
// Start again with other options replaces both.
class LoopbackServerTest : public ::testing::Test {
 protected:
  void Start(const ServerOptions& options) {
    stub_.reset();
    server_.reset();
    absl::StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
    ASSERT_GT(server_->port(), 0);
    channel_ = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
    stub_ = Sessions::NewStub(channel_);
  }

  // Options for a server on 127.0.0.1:0 with room for `max_sessions`.
  static ServerOptions LoopbackOptions(int max_sessions) {
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.max_sessions = max_sessions;
    return o;
  }

  std::unique_ptr<Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<Sessions::Stub> stub_;
};

class LiveTest : public LoopbackServerTest {
 protected:
  void SetUp() override { Start(Options()); }

  static ServerOptions Options() { return LoopbackOptions(8); }
  // Options() with `dir` as the data directory.
  static ServerOptions DataDirOptions(const std::string& dir) {
    ServerOptions o = Options();
    o.data_dir = dir;
    return o;
  }

  Session Create(const std::string& builtin, int levels, bool paused) {
    CreateSessionRequest r;
    r.set_builtin_scene(builtin);
    r.set_levels_override(levels);
    r.set_start_paused(paused);
    return CreateFrom(r);
  }
  Session CreateText(const std::string& text, bool paused) {
    CreateSessionRequest r;
    r.set_scene_text(text);
    r.set_start_paused(paused);
    return CreateFrom(r);
  }
  // A Watch of `s` (default rate, deadline a minute away) on `context`.
  std::unique_ptr<grpc::ClientReader<Frame>> WatchOf(const Session& s,
                                                     grpc::ClientContext* context) {
    context->set_deadline(Deadline());
    WatchRequest r;
    *r.mutable_session() = RefOf(s);
    return stub_->Watch(context, r);
  }
  // Inspect with `r`, a minute's deadline.
  grpc::Status Inspect(const InspectRequest& r, InspectReply* reply) {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    return stub_->Inspect(&context, r, reply);
  }
  // The status of a Watch the server refuses: it ends before any frame.
  grpc::Status RefusedWatch(const WatchRequest& r) {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    auto reader = stub_->Watch(&context, r);
    Frame f;
    EXPECT_FALSE(reader->Read(&f)) << "a refused watch sent a frame";
    return reader->Finish();
  }
  Session CreateFrom(const CreateSessionRequest& r) {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    Session s;
    const grpc::Status status = stub_->CreateSession(&context, r, &s);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return s;
  }
};

// Reads frames into a decoder until one at `step` arrives.
inline ::testing::AssertionResult ReadUntilStep(grpc::ClientReader<Frame>& reader,
                                         client::SurfaceDecoder& decoder, int64_t step,
                                         std::vector<Frame>* frames = nullptr) {
  Frame f;
  while (decoder.step() != step || !decoder.has_keyframe()) {
    if (!reader.Read(&f)) return ::testing::AssertionFailure() << "stream ended before step " << step;
    const absl::Status s = decoder.Apply(f);
    if (!s.ok()) return ::testing::AssertionFailure() << "frame at step " << f.step() << ": " << s;
    if (frames != nullptr) frames->push_back(f);
    if (f.step() > step) return ::testing::AssertionFailure() << "passed step " << step;
  }
  return ::testing::AssertionSuccess();
}

// Whether `watch` gives a frame (its first).
inline bool ReadsAFrame(grpc::ClientReader<Frame>& watch) {
  Frame f;
  return watch.Read(&f);
}

// Reads `watch` to its end; it and `commands` must finish UNAVAILABLE, the
// watch saying `why`, and `commands` have no reply left.
inline void ExpectStreamsEndUnavailable(grpc::ClientReader<Frame>& watch,
                                        ::dynsolid::testing::CommandStream& commands,
                                        const std::string& why) {
  Frame f;
  while (watch.Read(&f)) {
  }
  const grpc::Status ws = watch.Finish();
  EXPECT_EQ(ws.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_THAT(ws.error_message(), ::testing::HasSubstr(why));
  CommandReply reply;
  EXPECT_FALSE(commands.Read(&reply));
  EXPECT_EQ(commands.Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
}

// Largest |decoded - server| / bound over every coordinate.
inline double WorstRatio(const client::SurfaceDecoder& d, const InspectReply& server) {
  const std::vector<double> p = d.surface().positions;
  EXPECT_EQ(static_cast<int>(p.size()), server.surface_positions_size());
  const double bound[3] = {d.surface().error_bound[0], d.surface().error_bound[1], d.surface().error_bound[2]};
  double worst = 0;
  for (int i = 0; i < server.surface_positions_size() && i < static_cast<int>(p.size()); ++i) {
    worst = std::max(worst, std::abs(p[i] - server.surface_positions(i)) / bound[i % 3]);
  }
  return worst;
}

}  // namespace dynsolid::server
