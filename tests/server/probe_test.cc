// The haptic probe stream (service.proto rpc Probe; server/probe.h) over
// loopback gRPC against an in-process server: contact model values on
// block3, painted stiffness, the reaction load denting the solid, refused
// poses, and the "contact" phase only while a probe is connected.
#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "dynsolid/service.grpc.pb.h"
#include "server/server.h"
#include "tests/testing/vec3.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;

using ProbeStream = grpc::ClientReaderWriter<ProbeRequest, ProbeReply>;
using CommandStream = grpc::ClientReaderWriter<CommandRequest, CommandReply>;

Vec3 V3(double x, double y, double z) {
  Vec3 v;
  testing::SetXyz(&v, x, y, z);
  return v;
}

class ProbeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.max_sessions = 4;
    // The probe's replies at normal priority (as docs/haptic.md runs a
    // haptic server): under SCHED_IDLE, beside two busy loops, they got no
    // core and the stream's 60 s deadline passed.
    o.stream_idle = false;
    absl::StatusOr<std::unique_ptr<Server>> server = Server::Start(o);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
    channel_ = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
    stub_ = Sessions::NewStub(channel_);
  }

  // block3 at one level, paused at step 0 (nothing moves unless asked).
  Session CreateBlock3(int levels = 1) {
    CreateSessionRequest request;
    request.set_builtin_scene("block3");
    request.set_levels_override(levels);
    request.set_start_paused(true);
    grpc::ClientContext context;
    Session s;
    const grpc::Status st = stub_->CreateSession(&context, request, &s);
    EXPECT_TRUE(st.ok()) << st.error_message();
    return s;
  }
  static SessionRef Ref(const Session& s) {
    SessionRef r;
    r.set_id(s.id());
    r.set_token(s.token());
    return r;
  }

  struct Probe {
    std::unique_ptr<grpc::ClientContext> context = std::make_unique<grpc::ClientContext>();
    std::unique_ptr<ProbeStream> rw;
    uint64_t seq = 0;
  };
  Probe OpenProbe(const Session& s, double near = 0) {
    Probe p;
    p.context->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    p.rw = stub_->Probe(p.context.get());
    ProbeRequest first;
    *first.mutable_session() = Ref(s);
    first.mutable_options()->set_near_distance(near);
    EXPECT_TRUE(p.rw->Write(first));
    return p;
  }
  // Sends a pose (seq from the probe's counter unless given).
  static void SendPose(Probe& p, double x, double y, double z, Vec3 force = Vec3(),
                       int64_t model_step = 0, std::optional<uint64_t> seq = std::nullopt) {
    ProbeRequest r;
    ProbePose* pose = r.mutable_pose();
    pose->set_seq(seq.has_value() ? *seq : ++p.seq);
    *pose->mutable_position() = V3(x, y, z);
    pose->mutable_orientation()->set_w(1);
    *pose->mutable_coupling_force() = force;
    pose->set_model_step(model_step);
    EXPECT_TRUE(p.rw->Write(r));
  }
  // Reads replies until `done` holds (or the stream ends).
  static ProbeReply ReadUntil(Probe& p, const std::function<bool(const ProbeReply&)>& done,
                              std::vector<PoseRejection>* rejections = nullptr) {
    ProbeReply r;
    for (int i = 0; i < 20000; ++i) {
      if (!p.rw->Read(&r)) {
        const grpc::Status st = p.rw->Finish();
        ADD_FAILURE() << "the probe stream ended: " << static_cast<int>(st.error_code()) << " "
                      << st.error_message();
        return r;
      }
      if (rejections != nullptr) {
        for (const PoseRejection& x : r.rejected()) rejections->push_back(x);
      }
      if (done(r)) return r;
      if (getenv("PROBE_TEST_DEBUG") != nullptr && i < 50) {
        std::printf("reply step %ld last_pose %lu model %d pose_seq %lu applied %g\n",
                    static_cast<long>(r.step()), static_cast<unsigned long>(r.last_pose_seq()),
                    r.has_model(), static_cast<unsigned long>(r.model().pose_seq()),
                    r.model().applied_force().z());
      }
    }
    ADD_FAILURE() << "no such reply";
    return r;
  }
  // Half-closes, reads what is left, and checks the stream ended OK.
  static void Close(Probe& p) {
    p.rw->WritesDone();
    ProbeReply r;
    while (p.rw->Read(&r)) {
    }
    const grpc::Status st = p.rw->Finish();
    EXPECT_TRUE(st.ok()) << st.error_message();
  }
  static ProbeReply ModelFor(Probe& p, uint64_t seq) {
    return ReadUntil(
        p, [seq](const ProbeReply& r) { return r.has_model() && r.model().pose_seq() >= seq; });
  }
  // The first model with its stiffness: the server builds the contact
  // stiffness off its loop, and models go out without it meanwhile.
  static ProbeReply StiffModelFor(Probe& p, uint64_t seq) {
    return ReadUntil(p, [seq](const ProbeReply& r) {
      return r.has_model() && r.model().pose_seq() >= seq && r.model().stiffness() > 0;
    });
  }

  // A command on its own stream; returns the reply.
  CommandReply Command(const Session& s, const std::string& text_proto_kind,
                       const std::function<void(dynsolid::Command*)>& fill) {
    grpc::ClientContext context;
    std::unique_ptr<CommandStream> rw = stub_->Commands(&context);
    CommandRequest r;
    *r.mutable_session() = Ref(s);
    r.set_client_id("probe-test-" + text_proto_kind);
    r.set_seq(++command_seq_);
    fill(r.mutable_command());
    EXPECT_TRUE(rw->Write(r));
    rw->WritesDone();
    CommandReply reply;
    EXPECT_TRUE(rw->Read(&reply));
    EXPECT_EQ(reply.code(), 0) << reply.message();
    EXPECT_TRUE(rw->Finish().ok());
    return reply;
  }
  // The session is paused: it is at `step` until the Step command runs.
  void StepAndWait(const Session& s, int64_t n) {
    const int64_t step = StatsOf(s).step();
    Command(s, "step", [n](dynsolid::Command* c) { c->mutable_step()->set_count(n); });
    Inspect(s, /*control=*/false, step + n);
  }
  InspectReply Inspect(const Session& s, bool control, int64_t wait_for_step = 0) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    InspectRequest r;
    *r.mutable_session() = Ref(s);
    r.set_control_positions(control);
    r.set_wait_for_step(wait_for_step);
    InspectReply reply;
    const grpc::Status st = stub_->Inspect(&context, r, &reply);
    EXPECT_TRUE(st.ok()) << st.error_message();
    return reply;
  }
  SessionStats StatsOf(const Session& s) {
    grpc::ClientContext context;
    SessionStats st;
    EXPECT_TRUE(stub_->GetStats(&context, Ref(s), &st).ok());
    return st;
  }
  static bool HasPhase(const SessionStats& s, const std::string& name) {
    for (const PhaseTime& p : s.phases()) {
      if (p.name() == name) return true;
    }
    return false;
  }

  std::unique_ptr<Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<Sessions::Stub> stub_;
  uint64_t command_seq_ = 0;
};

// block3's boundary at rest is the box [0, 3]^3: the model's point, normal
// and distance are known exactly.
TEST_F(ProbeTest, ContactModelOnBlock3IsTheBoxsPointAndNormal) {
  const Session s = CreateBlock3();
  Probe p = OpenProbe(s);
  SendPose(p, 1.3, 1.7, 3.05);
  const ProbeReply r = StiffModelFor(p, 1);
  const ContactModel& m = r.model();
  EXPECT_EQ(m.step(), 0);
  EXPECT_NEAR(m.point().x(), 1.3, 1e-9);
  EXPECT_NEAR(m.point().y(), 1.7, 1e-9);
  EXPECT_NEAR(m.point().z(), 3.0, 1e-9);
  EXPECT_NEAR(m.material_point().z(), 3.0, 1e-9);
  EXPECT_NEAR(m.normal().z(), 1.0, 1e-12);
  EXPECT_NEAR(m.distance(), 0.05, 1e-9);
  EXPECT_GT(m.stiffness(), 0);
  EXPECT_GT(m.static_stiffness(), 0);
  EXPECT_GE(m.stiffness(), m.static_stiffness());
  EXPECT_GT(m.damping(), 0);
  EXPECT_GT(m.effective_mass(), 0);
  EXPECT_EQ(m.compliance_size(), 9);
  EXPECT_NEAR(m.horizon(), 0.03, 1e-15);
  std::printf(
      "block3 top (1.3, 1.7): k %.4g N/m at tau %.3f s, static %.4g N/m, b %.4g N s/m, "
      "m %.4g kg\n",
      m.stiffness(), m.horizon(), m.static_stiffness(), m.damping(), m.effective_mass());
  // Beside the +x face.
  SendPose(p, 3.1, 1.0, 1.5);
  const ContactModel side = ModelFor(p, 2).model();
  EXPECT_NEAR(side.point().x(), 3.0, 1e-9);
  EXPECT_NEAR(side.normal().x(), 1.0, 1e-12);
  EXPECT_NEAR(side.distance(), 0.1, 1e-9);
  // Far above (default near distance: 10 % of 3 m): replies without a model.
  SendPose(p, 1.5, 1.5, 4.5);
  const ProbeReply far =
      ReadUntil(p, [](const ProbeReply& r) { return r.last_pose_seq() >= 3 && !r.has_model(); });
  EXPECT_FALSE(far.has_model());
  Close(p);
}

// Painting half the block ten times stiffer: the probe feels it there.
TEST_F(ProbeTest, PaintedStifferHalfHasLargerEffectiveStiffness) {
  const Session s = CreateBlock3();
  Probe p = OpenProbe(s);
  auto static_at = [&](double x, double y) {
    SendPose(p, x, y, 3.05);
    return StiffModelFor(p, p.seq).model();
  };
  const ContactModel soft0 = static_at(0.75, 1.5), stiff0 = static_at(2.25, 1.5);
  Command(s, "paint", [](dynsolid::Command* c) {
    MaterialPaint* paint = c->mutable_paint_material();
    paint->mutable_region()->mutable_box()->mutable_min()->set_x(1.5);
    paint->mutable_region()->mutable_box()->mutable_min()->set_y(-1);
    paint->mutable_region()->mutable_box()->mutable_min()->set_z(-1);
    *paint->mutable_region()->mutable_box()->mutable_max() = V3(4, 4, 4);
    paint->mutable_material()->set_young_modulus(1e6);
    paint->set_strength(1);
    paint->set_falloff(0.1);
  });
  const ContactModel soft1 = static_at(0.75, 1.5), stiff1 = static_at(2.25, 1.5);
  std::printf(
      "static stiffness before / after painting x > 1.5 ten times stiffer: soft side "
      "%.4g / %.4g, painted side %.4g / %.4g N/m; over tau: %.4g / %.4g, %.4g / %.4g\n",
      soft0.static_stiffness(), soft1.static_stiffness(), stiff0.static_stiffness(),
      stiff1.static_stiffness(), soft0.stiffness(), soft1.stiffness(), stiff0.stiffness(),
      stiff1.stiffness());
  EXPECT_NEAR(soft0.static_stiffness(), stiff0.static_stiffness(), 0.01 * soft0.static_stiffness())
      << "symmetric before the paint";
  EXPECT_GT(stiff1.static_stiffness(), 3.0 * soft1.static_stiffness());
  EXPECT_GT(stiff1.stiffness(), 1.2 * soft1.stiffness());
  Close(p);
}

// Across a topology edit the probe goes on: the edited solid's contact
// stiffness is built off the simulation loop, models for the new topology
// come without stiffness meanwhile, and then with it again.
TEST_F(ProbeTest, ProbeGoesOnAcrossATopologyEditAsItsStiffnessIsRebuilt) {
  const Session s = CreateBlock3();
  Probe p = OpenProbe(s);
  SendPose(p, 1.5, 1.5, 3.05);
  const ContactModel before = StiffModelFor(p, p.seq).model();
  const CommandReply edit = Command(s, "extrude", [](dynsolid::Command* c) {
    ExtrudeFaces* e = c->mutable_edit()->mutable_extrude_faces();
    *e->add_near() = V3(1.5, 1.5, 3);
    e->set_distance(1);
    e->set_layers(1);
  });
  ASSERT_EQ(edit.code(), 0) << edit.message();
  // The probe at the top of the new column (z = 4).
  SendPose(p, 1.5, 1.5, 4.05);
  // Models for the new topology that went out while its stiffness was
  // being built carry stiffness 0 with the rest of the stiffness terms
  // (how many depends on how long the build takes against the step: none
  // when it is done within a step), the geometry in place.
  int unknown = 0;
  const ProbeReply after = ReadUntil(p, [&](const ProbeReply& r) {
    if (!r.has_model() || r.model().topology_version() == before.topology_version()) return false;
    if (r.model().stiffness() == 0) {
      ++unknown;
      EXPECT_EQ(r.model().static_stiffness(), 0);
      EXPECT_EQ(r.model().effective_mass(), 0);
      const auto& n = r.model().normal();
      EXPECT_NEAR(n.x() * n.x() + n.y() * n.y() + n.z() * n.z(), 1.0, 1e-9);
    }
    // A model for the earlier pose (now inside the column) does not count:
    // the model's own pose, not the reply's last received one (a pose can
    // arrive after the refresh that made this model began).
    return r.model().stiffness() > 0 && r.model().pose_seq() >= p.seq;
  });
  std::printf("%d models went out while the stiffness was being built\n", unknown);
  EXPECT_GT(after.model().point().z(), 3.5) << "on the new column";
  EXPECT_GT(after.model().stiffness(), 0);
  EXPECT_GT(after.model().static_stiffness(), 0);
  std::printf("static stiffness at the top: %.4g N/m before, %.4g N/m on the extruded column\n",
              before.static_stiffness(), after.model().static_stiffness());
  Close(p);
}

// A probe pushing in dents the solid: the reaction (minus the reported
// coupling force) acts at the contact material point.
TEST_F(ProbeTest, PushingProbeDentsTheSolidAtTheContactPoint) {
  const Session s = CreateBlock3();
  Probe p = OpenProbe(s);
  SendPose(p, 1.5, 1.5, 3.01);
  const ContactModel m0 = ModelFor(p, 1).model();
  const InspectReply before = Inspect(s, true);
  // The bridge renders +z on the device: the solid gets -z.
  SendPose(p, 1.5, 1.5, 2.99, V3(0, 0, 200.0), m0.step());
  ModelFor(p, 2);
  // Renewed every 10 steps, as a bridge does at 1 kHz: a pose older than
  // ProbeLimits::pose_timeout (wall time) no longer pushes, and a loaded
  // machine can take that long for 300 steps.
  for (int chunk = 0; chunk < 30; ++chunk) {
    StepAndWait(s, 10);
    SendPose(p, 1.5, 1.5, 2.99, V3(0, 0, 200.0), m0.step());
  }
  // The next refresh shows the renewed force acting.
  const ContactModel m1 =
      ReadUntil(p, [](const ProbeReply& r) {
        return r.has_model() && r.model().pose_seq() >= 32 && r.model().applied_force().z() < 0;
      }).model();
  EXPECT_NEAR(m1.applied_force().z(), -200.0, 1e-9) << "the load that acted";
  EXPECT_LT(m1.point().z(), 3.0 - 1e-4) << "the contact point moved along the push";
  EXPECT_NEAR(m1.material_point().x(), 1.5, 1e-6);
  const InspectReply after = Inspect(s, true);
  double dz = 0;
  for (int i = 2; i < after.control_positions_size(); i += 3) {
    dz = std::min(dz, after.control_positions(i) - before.control_positions(i));
  }
  std::printf(
      "after 300 steps at 200 N: contact point z %.6f (dent %.3g mm), lowest control "
      "point moved %.3g mm\n",
      m1.point().z(), 1e3 * (3.0 - m1.point().z()), 1e3 * dz);
  EXPECT_LT(dz, -1e-5);
  const SessionStats st = StatsOf(s);
  EXPECT_EQ(st.probes(), 1);
  ASSERT_EQ(st.probe_details_size(), 1);
  EXPECT_NEAR(st.probe_details(0).applied_force().z(), -200.0, 1e-9);
  EXPECT_TRUE(HasPhase(st, "contact"));
  Close(p);
}

// Bad poses are refused with a status and never reach the solid: a session
// that received only bad (force-carrying) poses steps exactly like one that
// received none.
TEST_F(ProbeTest, BadPosesAreRefusedAndChangeNothing) {
  const Session s = CreateBlock3();
  const Session reference = CreateBlock3();
  Probe p = OpenProbe(s);
  const Vec3 push = V3(0, 0, 500.0);
  std::vector<PoseRejection> refused;
  SendPose(p, NAN, 1.5, 2.9, push);                // 1: non-finite position
  SendPose(p, 1.5, 1.5, 2.9, V3(0, INFINITY, 0));  // 2: non-finite force
  SendPose(p, 1.5, 1.5, 2.9, V3(0, 0, 1e9));       // 3: force above the limit
  SendPose(p, 100.0, 1.5, 2.9, push);              // 4: far outside the bounds
  ReadUntil(
      p, [](const ProbeReply& r) { return r.rejected_total() >= 4; }, &refused);
  SendPose(p, 1.5, 1.5, 3.5, Vec3(), 0, 10);  // seq 10: fine, no force, far away
  ReadUntil(
      p, [](const ProbeReply& r) { return r.last_pose_seq() >= 10; }, &refused);
  SendPose(p, 1.5, 1.5, 2.9, push, 0, 7);   // seq 7 < 10: out of order
  SendPose(p, 1.5, 1.5, 2.9, push, 0, 10);  // seq 10 again
  ReadUntil(
      p, [](const ProbeReply& r) { return r.rejected_total() >= 6; }, &refused);
  ASSERT_EQ(refused.size(), 6u);
  EXPECT_EQ(refused[0].code(), static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_THAT(refused[0].message(), HasSubstr("pose.position.x must be finite"));
  EXPECT_THAT(refused[1].message(), HasSubstr("pose.coupling_force.y must be finite"));
  EXPECT_THAT(refused[2].message(), HasSubstr("above the server's limit"));
  EXPECT_EQ(refused[3].code(), static_cast<int>(grpc::StatusCode::OUT_OF_RANGE));
  EXPECT_THAT(refused[3].message(), HasSubstr("outside its bounds"));
  EXPECT_EQ(refused[4].seq(), 7u);
  EXPECT_EQ(refused[4].code(), static_cast<int>(grpc::StatusCode::OUT_OF_RANGE));
  EXPECT_THAT(refused[4].message(), HasSubstr("pose.seq: 7 is not above"));
  EXPECT_EQ(refused[5].seq(), 10u);
  StepAndWait(s, 50);
  StepAndWait(reference, 50);
  const InspectReply a = Inspect(s, true), b = Inspect(reference, true);
  ASSERT_EQ(a.control_positions_size(), b.control_positions_size());
  for (int i = 0; i < a.control_positions_size(); ++i) {
    ASSERT_EQ(a.control_positions(i), b.control_positions(i)) << "coordinate " << i;
  }
  const SessionStats st = StatsOf(s);
  ASSERT_EQ(st.probe_details_size(), 1);
  EXPECT_EQ(st.probe_details(0).poses_rejected(), 6);
  EXPECT_EQ(st.probe_details(0).applied_force().z(), 0.0);
  Close(p);
}

// No probe: no contact work (no "contact" phase); with one: the phase; when
// it leaves its load is removed.
TEST_F(ProbeTest, ContactPhaseOnlyWhileAProbeIsConnected) {
  const Session s = CreateBlock3();
  StepAndWait(s, 20);
  SessionStats st = StatsOf(s);
  EXPECT_FALSE(HasPhase(st, "contact"));
  EXPECT_EQ(st.probes(), 0);
  {
    Probe p = OpenProbe(s);
    SendPose(p, 1.5, 1.5, 3.01);
    const ContactModel m = ModelFor(p, 1).model();
    SendPose(p, 1.5, 1.5, 3.0, V3(0, 0, 100.0), m.step());
    ModelFor(p, 2);
    StepAndWait(s, 20);
    st = StatsOf(s);
    EXPECT_TRUE(HasPhase(st, "contact"));
    EXPECT_EQ(st.probes(), 1);
    EXPECT_EQ(st.probes_total(), 1);
    Close(p);
  }
  StepAndWait(s, 2);
  st = StatsOf(s);
  EXPECT_EQ(st.probes(), 0);
  EXPECT_EQ(st.probe_details_size(), 0);
}

TEST_F(ProbeTest, WrongTokenAndTooManyProbesAreRefused) {
  const Session s = CreateBlock3();
  {
    Session bad = s;
    bad.set_token(std::string(32, '0'));
    Probe p = OpenProbe(bad);
    ProbeReply r;
    EXPECT_FALSE(p.rw->Read(&r));
    const grpc::Status st = p.rw->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::PERMISSION_DENIED) << st.error_message();
  }
  std::vector<Probe> probes;
  for (int i = 0; i < 4; ++i) {
    probes.push_back(OpenProbe(s));
    SendPose(probes.back(), 1.5, 1.5, 3.5);
    ReadUntil(probes.back(), [](const ProbeReply& r) { return r.last_pose_seq() >= 1; });
  }
  Probe fifth = OpenProbe(s);
  ProbeReply r;
  EXPECT_FALSE(fifth.rw->Read(&r));
  const grpc::Status st = fifth.rw->Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
  for (Probe& p : probes) {
    Close(p);
  }
}

}  // namespace
}  // namespace dynsolid::server
