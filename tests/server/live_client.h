// A small synchronous test client for the live parts of dynsolid.Sessions
// (commands, watch, inspect, stats), shared by the loopback tests and the
// kill -9 test. Speaks only service.proto.
#pragma once

#include <chrono>
#include <cstring>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "google/protobuf/text_format.h"

#include "dynsolid/service.grpc.pb.h"
#include "tests/testing/vec3.h"

namespace dynsolid::testing {

inline std::chrono::system_clock::time_point Deadline(int seconds = 60) {
  return std::chrono::system_clock::now() + std::chrono::seconds(seconds);
}

// A free 3 x 3 x 3 block at one level spinning about z (no damping, no
// constraints): every surface vertex moves at every step, for ever.
inline std::string SpinningSceneText() {
  return R"(
    name: "spinner"
    mesh { block { nx: 3 ny: 3 nz: 3 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 } }
    initial { angular_velocity { z: 2 } }
    solver { model: LOCAL_FRAME integrator: CENTRAL_DIFFERENCE time_step: 1e-3 }
  )";
}

inline SessionRef RefOf(const Session& s) {
  SessionRef r;
  r.set_id(s.id());
  r.set_token(s.token());
  return r;
}

// A paused session of the builtin block3 at one level.
inline CreateSessionRequest PausedBlock3Request() {
  CreateSessionRequest r;
  r.set_builtin_scene("block3");
  r.set_levels_override(1);
  r.set_start_paused(true);
  return r;
}
inline grpc::Status CreatePausedBlock3(Sessions::Stub& stub, Session* out) {
  grpc::ClientContext context;
  context.set_deadline(Deadline());
  return stub.CreateSession(&context, PausedBlock3Request(), out);
}

// One Commands stream; Send writes a command and reads its reply.
class CommandStream {
 public:
  CommandStream(Sessions::Stub& stub, const Session& session, std::string client_id,
                int deadline_seconds = 120)
      : session_(session), client_id_(std::move(client_id)) {
    context_.set_deadline(Deadline(deadline_seconds));
    stream_ = stub.Commands(&context_);
  }
  ~CommandStream() {
    if (!closed_) Cancel();
  }

  bool Write(uint64_t seq, const Command& command, bool with_session = true) {
    CommandRequest r;
    if (with_session || first_) *r.mutable_session() = RefOf(session_);
    first_ = false;
    r.set_client_id(client_id_);
    r.set_seq(seq);
    *r.mutable_command() = command;
    return stream_->Write(r);
  }
  bool WriteRaw(const CommandRequest& r) {
    first_ = false;
    return stream_->Write(r);
  }
  bool Read(CommandReply* reply) { return stream_->Read(reply); }

  CommandReply Send(uint64_t seq, const Command& command) {
    CommandReply reply;
    EXPECT_TRUE(Write(seq, command)) << "write of seq " << seq;
    EXPECT_TRUE(Read(&reply)) << "reply to seq " << seq << ": " << Finish().error_message();
    return reply;
  }
  grpc::Status Finish() {
    stream_->WritesDone();
    closed_ = true;
    return stream_->Finish();
  }
  // Drops the connection's call as a broken client would.
  void Cancel() {
    context_.TryCancel();
    closed_ = true;
    CommandReply ignored;
    while (stream_->Read(&ignored)) {
    }
    stream_->Finish();
  }

 private:
  Session session_;
  std::string client_id_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<CommandRequest, CommandReply>> stream_;
  bool first_ = true;
  bool closed_ = false;
};

inline Command StepCommand(int64_t n) {
  Command c;
  c.mutable_step()->set_count(n);
  return c;
}
inline Command ForceCommand(double x, double y, double z, double fx, double fy, double fz) {
  Command c;
  PointForce* f = c.mutable_add_point_force();
  SetXyz(f->mutable_position(), x, y, z);
  SetXyz(f->mutable_force(), fx, fy, fz);
  return c;
}

// Parses each text into the command it is paired with; fails naming the
// first text that does not parse.
inline ::testing::AssertionResult ParseCommands(
    std::initializer_list<std::pair<Command*, const char*>> commands) {
  for (const auto& [command, text] : commands) {
    if (!google::protobuf::TextFormat::ParseFromString(text, command)) {
      return ::testing::AssertionFailure() << "cannot parse " << text;
    }
  }
  return ::testing::AssertionSuccess();
}

inline InspectReply InspectAt(Sessions::Stub& stub, const Session& s, int64_t step,
                              bool surface = true, bool control = true,
                              grpc::Status* status_out = nullptr) {
  grpc::ClientContext context;
  context.set_deadline(Deadline(120));
  InspectRequest r;
  *r.mutable_session() = RefOf(s);
  r.set_wait_for_step(step);
  r.set_surface_positions(surface);
  r.set_control_positions(control);
  InspectReply reply;
  const grpc::Status status = stub.Inspect(&context, r, &reply);
  if (status_out != nullptr) {
    *status_out = status;
  } else {
    EXPECT_TRUE(status.ok()) << status.error_message();
  }
  return reply;
}

inline SessionStats StatsOf(Sessions::Stub& stub, const Session& s) {
  grpc::ClientContext context;
  context.set_deadline(Deadline());
  SessionStats stats;
  const grpc::Status status = stub.GetStats(&context, RefOf(s), &stats);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return stats;
}

// Bitwise equality of two double arrays (NaN-safe, -0 != +0).
template <typename A, typename B>
bool BitIdentical(const A& a, const B& b) {
  if (a.size() != b.size()) return false;
  for (int i = 0; i < static_cast<int>(a.size()); ++i) {
    const double x = a[i], y = b[i];
    if (std::memcmp(&x, &y, sizeof(double)) != 0) return false;
  }
  return true;
}

}  // namespace dynsolid::testing
