// dynsolid.Sessions over loopback gRPC against an in-process server
// listening on 127.0.0.1:0.
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "dynsolid/service.grpc.pb.h"
#include "health.grpc.pb.h"
#include "live_fixture.h"
#include "server/server.h"
#include "server/solid_builder.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::server {
namespace {

using ::testing::_;
using ::testing::AllOf;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::MatchesRegex;
using ::testing::Not;
using ::testing::StartsWith;

MATCHER_P2(GrpcStatusIs, code, message_matcher,
           "has gRPC code " + ::testing::PrintToString(static_cast<int>(code))) {
  *result_listener << "status is " << static_cast<int>(arg.error_code()) << ": "
                   << arg.error_message();
  return arg.error_code() == code &&
         ::testing::Value(arg.error_message(), message_matcher);
}

MATCHER(GrpcOk, "is OK") {
  *result_listener << "status is " << static_cast<int>(arg.error_code()) << ": "
                   << arg.error_message();
  return arg.ok();
}

class SessionsServiceTest : public LoopbackServerTest {
 protected:
  void SetUp() override { Start(DefaultOptions()); }

  static ServerOptions DefaultOptions() { return LoopbackOptions(4); }

  grpc::Status Create(const CreateSessionRequest& request, Session* reply) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    return stub_->CreateSession(&context, request, reply);
  }
  grpc::Status CreateBuiltin(const std::string& name, Session* reply, int levels = -1) {
    CreateSessionRequest request;
    request.set_builtin_scene(name);
    if (levels >= 0) request.set_levels_override(levels);
    return Create(request, reply);
  }
  grpc::Status CreateFromText(const std::string& text, Session* reply) {
    CreateSessionRequest request;
    request.set_scene_text(text);
    return Create(request, reply);
  }
  grpc::Status Get(const std::string& id, const std::string& token, Session* reply) {
    grpc::ClientContext context;
    SessionRef ref;
    ref.set_id(id);
    ref.set_token(token);
    return stub_->GetSession(&context, ref, reply);
  }
  grpc::Status Close(const std::string& id, const std::string& token) {
    grpc::ClientContext context;
    SessionRef ref;
    ref.set_id(id);
    ref.set_token(token);
    google::protobuf::Empty reply;
    return stub_->CloseSession(&context, ref, &reply);
  }
  std::vector<std::string> ListedIds() {
    grpc::ClientContext context;
    ListSessionsResponse reply;
    const grpc::Status status = stub_->ListSessions(&context, ListSessionsRequest(), &reply);
    EXPECT_THAT(status, GrpcOk());
    std::vector<std::string> ids;
    for (const auto& e : reply.sessions()) ids.push_back(e.id());
    return ids;
  }
};

// block3: 27 unit hexahedra, two MacCracken-Joy levels: 27 * 8^2 = 1728
// cells, (12 + 1)^3 = 2197 vertices (all hexahedral, so no virtual nodes),
// and the interior (12 - 2)^3 = 1000 cells are cubic B-spline elements.
TEST_F(SessionsServiceTest, CreateBlock3AtTwoLevelsReturnsItsDiscretization) {
  Session s;
  ASSERT_THAT(CreateBuiltin("block3", &s, 2), GrpcOk());
  EXPECT_THAT(s.id(), MatchesRegex("[0-9a-f]{16}"));
  EXPECT_THAT(s.token(), MatchesRegex("[0-9a-f]{32}"));
  EXPECT_EQ(s.scene_name(), "block3");
  EXPECT_GT(s.created().seconds(), 0);
  const SolidStats& st = s.stats();
  EXPECT_EQ(st.control_cells(), 27);
  EXPECT_EQ(st.control_vertices(), 64);
  EXPECT_EQ(st.levels(), 2);
  EXPECT_EQ(st.cells(), 1728);
  EXPECT_EQ(st.vertices(), 2197);
  EXPECT_EQ(st.nodes(), 2197);
  EXPECT_EQ(st.cubic_elements(), 1000);
  EXPECT_EQ(st.linear_elements(), 1728 - 1000);
  EXPECT_EQ(st.pyramid_elements(), 0);
  EXPECT_EQ(st.pyramid_cells(), 0);
  EXPECT_DOUBLE_EQ(st.cubic_fraction(), 1000.0 / 1728.0);
  EXPECT_DOUBLE_EQ(st.linear_fraction(), 728.0 / 1728.0);
  EXPECT_DOUBLE_EQ(st.pyramid_fraction(), 0.0);
  // The boundary of a 12 x 12 x 12 grid of cells: a sphere.
  EXPECT_EQ(st.boundary_faces(), 6 * 12 * 12);
  EXPECT_EQ(st.boundary_vertices(), 6 * 12 * 12 + 2);
  EXPECT_EQ(st.boundary_euler(), 2);
}

TEST_F(SessionsServiceTest, LevelsOverrideAbsentOrMinusOneKeepsTheScenesLevels) {
  Session absent, keep, one;
  ASSERT_THAT(CreateBuiltin("block3", &absent), GrpcOk());
  EXPECT_EQ(absent.stats().levels(), 2);  // scenes/block3.textproto
  ASSERT_THAT(CreateBuiltin("block3", &one, 1), GrpcOk());
  EXPECT_EQ(one.stats().levels(), 1);
  EXPECT_EQ(one.stats().cells(), 27 * 8);
  CreateSessionRequest request;
  request.set_builtin_scene("block3");
  request.set_levels_override(-1);
  ASSERT_THAT(Create(request, &keep), GrpcOk());
  EXPECT_EQ(keep.stats().levels(), 2);
  EXPECT_NE(keep.id(), absent.id());
  EXPECT_NE(keep.token(), absent.token());
}

TEST_F(SessionsServiceTest, LevelsOverrideOutOfRangeIsInvalidArgumentNamingTheField) {
  Session s;
  EXPECT_THAT(CreateBuiltin("block3", &s, 7),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(HasSubstr("levels_override"), HasSubstr("got 7"))));
  EXPECT_THAT(ListedIds(), IsEmpty());
}

TEST_F(SessionsServiceTest, GetWithItsTokenReturnsTheSession) {
  Session created, got;
  ASSERT_THAT(CreateBuiltin("block3", &created, 1), GrpcOk());
  ASSERT_THAT(Get(created.id(), created.token(), &got), GrpcOk());
  EXPECT_EQ(got.id(), created.id());
  EXPECT_EQ(got.scene_name(), "block3");
  EXPECT_EQ(got.stats().cells(), created.stats().cells());
  EXPECT_EQ(got.created().seconds(), created.created().seconds());
}

TEST_F(SessionsServiceTest, WrongOrMissingTokenIsPermissionDenied) {
  Session created, got;
  ASSERT_THAT(CreateBuiltin("block3", &created, 1), GrpcOk());
  std::string wrong = created.token();
  wrong[0] = wrong[0] == '0' ? '1' : '0';
  EXPECT_THAT(Get(created.id(), wrong, &got),
              GrpcStatusIs(grpc::StatusCode::PERMISSION_DENIED, HasSubstr("does not match")));
  EXPECT_THAT(Get(created.id(), "", &got),
              GrpcStatusIs(grpc::StatusCode::PERMISSION_DENIED, HasSubstr("missing")));
  EXPECT_THAT(Get(created.id(), created.token() + "0", &got),
              GrpcStatusIs(grpc::StatusCode::PERMISSION_DENIED, HasSubstr("does not match")));
  // The denied response carries no token.
  EXPECT_THAT(got.token(), IsEmpty());
  // Closing needs the token too, and a denied close changes nothing.
  EXPECT_THAT(Close(created.id(), wrong), GrpcStatusIs(grpc::StatusCode::PERMISSION_DENIED,
                                                       HasSubstr(created.id())));
  EXPECT_THAT(ListedIds(), ElementsAre(created.id()));
}

TEST_F(SessionsServiceTest, UnknownIdIsNotFound) {
  Session got;
  EXPECT_THAT(Get("0123456789abcdef", "00000000000000000000000000000000", &got),
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("0123456789abcdef")));
  EXPECT_THAT(Close("0123456789abcdef", "00000000000000000000000000000000"),
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("0123456789abcdef")));
  EXPECT_THAT(Get("", "", &got),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("id")));
}

TEST_F(SessionsServiceTest, InvalidSceneTextIsInvalidArgumentNamingTheField) {
  Session s;
  EXPECT_THAT(CreateFromText("name: \"bad\"\nmesh {\n  block { nx: 0 ny: 3 nz: 3 }\n}\n", &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(StartsWith("scene_text:"), HasSubstr("mesh.block.nx"))));
  EXPECT_THAT(CreateFromText("mesh { block { nx: 2 ny: 2 nz: 2 } }\nsubdivision { levels: 9 }\n",
                             &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(StartsWith("scene_text:2:"), HasSubstr("subdivision.levels"))));
  // Not text format at all: the parser's position.
  EXPECT_THAT(CreateFromText("mesh { blok { } }", &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(StartsWith("scene_text:1:"), HasSubstr("blok"))));
  // No source at all.
  EXPECT_THAT(Create(CreateSessionRequest(), &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("scene_source")));
  EXPECT_THAT(ListedIds(), IsEmpty());
}

TEST_F(SessionsServiceTest, UnknownBuiltinSceneIsNotFoundListingTheKnownOnes) {
  Session s;
  EXPECT_THAT(CreateBuiltin("no_such_scene", &s),
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND,
                           AllOf(HasSubstr("no_such_scene"), HasSubstr("block3"))));
}

TEST_F(SessionsServiceTest, SceneTextFromAClientMayNotNameAMeshFile) {
  Session s;
  EXPECT_THAT(CreateFromText("name: \"sneaky\"\nmesh { file: \"/etc/passwd\" }\n", &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(StartsWith("scene_text"), HasSubstr("mesh.file"))));
  CreateSessionRequest request;
  request.mutable_scene()->mutable_mesh()->set_file("meshes/mixed.msh");
  EXPECT_THAT(Create(request, &s),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("mesh.file")));
  EXPECT_THAT(ListedIds(), IsEmpty());
}

TEST_F(SessionsServiceTest, SceneTextAndSceneMessageBuildLikeTheBuiltin) {
  Session from_text, from_message;
  ASSERT_THAT(CreateFromText("name: \"cube\"\nmesh { block { nx: 3 ny: 3 nz: 3 } }\n"
                             "subdivision { levels: 2 }\n",
                             &from_text),
              GrpcOk());
  EXPECT_EQ(from_text.scene_name(), "cube");
  EXPECT_EQ(from_text.stats().cells(), 1728);
  EXPECT_EQ(from_text.stats().cubic_elements(), 1000);

  CreateSessionRequest request;
  Scene* scene = request.mutable_scene();
  scene->set_name("cube");
  scene->mutable_mesh()->mutable_block()->set_nx(2);
  scene->mutable_mesh()->mutable_block()->set_ny(2);
  scene->mutable_mesh()->mutable_block()->set_nz(2);
  scene->mutable_subdivision()->set_levels(1);
  ASSERT_THAT(Create(request, &from_message), GrpcOk());
  EXPECT_EQ(from_message.stats().cells(), 8 * 8);

  scene->mutable_mesh()->mutable_block()->set_nx(0);
  EXPECT_THAT(Create(request, &from_message),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           AllOf(StartsWith("scene: "), HasSubstr("mesh.block.nx"))));
}

TEST_F(SessionsServiceTest, ListShowsOpenSessionsOldestFirstAndCloseRemovesThem) {
  Session a, b;
  ASSERT_THAT(CreateBuiltin("block3", &a, 0), GrpcOk());
  ASSERT_THAT(CreateBuiltin("torus", &b, 0), GrpcOk());
  {
    grpc::ClientContext context;
    ListSessionsResponse reply;
    ASSERT_THAT(stub_->ListSessions(&context, ListSessionsRequest(), &reply), GrpcOk());
    ASSERT_EQ(reply.sessions_size(), 2);
    EXPECT_EQ(reply.sessions(0).id(), a.id());
    EXPECT_EQ(reply.sessions(0).scene_name(), "block3");
    EXPECT_EQ(reply.sessions(1).id(), b.id());
    EXPECT_EQ(reply.sessions(1).scene_name(), "torus");
    EXPECT_GT(reply.sessions(1).created().seconds(), 0);
    // No token anywhere in the listing.
    EXPECT_THAT(reply.SerializeAsString(), Not(HasSubstr(a.token())));
    EXPECT_THAT(reply.SerializeAsString(), Not(HasSubstr(b.token())));
  }
  ASSERT_THAT(Close(a.id(), a.token()), GrpcOk());
  EXPECT_THAT(ListedIds(), ElementsAre(b.id()));
  Session got;
  EXPECT_THAT(Get(a.id(), a.token(), &got), GrpcStatusIs(grpc::StatusCode::NOT_FOUND, _));
  EXPECT_THAT(Close(a.id(), a.token()), GrpcStatusIs(grpc::StatusCode::NOT_FOUND, _));
  ASSERT_THAT(Close(b.id(), b.token()), GrpcOk());
  EXPECT_THAT(ListedIds(), IsEmpty());
}

TEST_F(SessionsServiceTest, MaxSessionsIsEnforcedAndClosingFreesASlot) {
  ServerOptions options = DefaultOptions();
  options.max_sessions = 2;
  Start(options);
  Session a, b, c;
  ASSERT_THAT(CreateBuiltin("block3", &a, 0), GrpcOk());
  ASSERT_THAT(CreateBuiltin("block3", &b, 0), GrpcOk());
  EXPECT_THAT(CreateBuiltin("block3", &c, 0),
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED, HasSubstr("maximum of 2")));
  ASSERT_THAT(Close(a.id(), a.token()), GrpcOk());
  EXPECT_THAT(CreateBuiltin("block3", &c, 0), GrpcOk());
}

TEST_F(SessionsServiceTest, ConcurrentCreatesNeverExceedMaxSessions) {
  ServerOptions options = DefaultOptions();
  options.max_sessions = 3;
  options.build_threads = 2;
  Start(options);
  constexpr int kClients = 8;
  std::vector<grpc::Status> results(kClients);
  std::vector<std::thread> clients;
  for (int i = 0; i < kClients; ++i) {
    clients.emplace_back([this, i, &results] {
      Session s;
      results[i] = CreateBuiltin("block3", &s, 2);
    });
  }
  for (std::thread& t : clients) t.join();
  int ok = 0, exhausted = 0;
  for (const grpc::Status& s : results) {
    ok += s.ok();
    exhausted += s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED;
  }
  EXPECT_EQ(ok, 3);
  EXPECT_EQ(exhausted, kClients - 3);
  EXPECT_EQ(ListedIds().size(), 3u);
}

TEST_F(SessionsServiceTest, SolidsLargerThanMaxCellsAreRefusedBeforeBuilding) {
  ServerOptions options = DefaultOptions();
  options.max_cells = 1000;
  Start(options);
  Session s;
  EXPECT_THAT(CreateBuiltin("block3", &s, 2),  // 1728 cells
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           AllOf(HasSubstr("1728 cells"), HasSubstr("limit of 1000"))));
  EXPECT_THAT(CreateBuiltin("block3", &s, 1), GrpcOk());  // 216 cells
}

TEST_F(SessionsServiceTest, MessagesOverMaxMessageBytesAreRejected) {
  ServerOptions options = DefaultOptions();
  options.max_message_bytes = 4096;
  Start(options);
  Session s;
  const std::string big_comment = "# " + std::string(8000, 'x') + "\n";
  EXPECT_THAT(CreateFromText(big_comment + "mesh { block { nx: 1 ny: 1 nz: 1 } }\n", &s),
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED, _));
  EXPECT_THAT(CreateFromText("mesh { block { nx: 1 ny: 1 nz: 1 } }\n", &s), GrpcOk());
}

TEST_F(SessionsServiceTest, HealthCheckReportsServing) {
  auto health = grpc::health::v1::Health::NewStub(channel_);
  grpc::ClientContext context;
  grpc::health::v1::HealthCheckRequest request;  // "" = the whole server
  grpc::health::v1::HealthCheckResponse reply;
  ASSERT_THAT(health->Check(&context, request, &reply), GrpcOk());
  EXPECT_EQ(reply.status(), grpc::health::v1::HealthCheckResponse::SERVING);
}

// --health_listen: a plaintext port with only the health service (for the
// kubelet's gRPC probes, which cannot speak TLS): SERVING while the server
// runs; no Sessions there.
TEST_F(SessionsServiceTest, AHealthOnlyPortReportsTheServerAndNothingElse) {
  ServerOptions o = DefaultOptions();
  o.health_listen = "127.0.0.1:0";
  Start(o);
  ASSERT_GT(server_->health_port(), 0);
  auto channel = grpc::CreateChannel(absl::StrCat("127.0.0.1:", server_->health_port()),
                                     grpc::InsecureChannelCredentials());
  auto health = grpc::health::v1::Health::NewStub(channel);
  grpc::health::v1::HealthCheckRequest request;
  grpc::health::v1::HealthCheckResponse reply;
  {
    grpc::ClientContext context;
    ASSERT_THAT(health->Check(&context, request, &reply), GrpcOk());
    EXPECT_EQ(reply.status(), grpc::health::v1::HealthCheckResponse::SERVING);
  }
  {
    auto sessions = Sessions::NewStub(channel);
    grpc::ClientContext context;
    ListSessionsRequest r;
    ListSessionsResponse out;
    EXPECT_EQ(sessions->ListSessions(&context, r, &out).error_code(),
              grpc::StatusCode::UNIMPLEMENTED);
  }
  // (Shutdown turns both ports' health to NOT_SERVING first, then drains:
  // server.cc; the window is too short to observe here without a race.)
}

// One request of raw bytes on a bidi call of `method` through a generic
// stub, then writes-done, one read and finish: each operation's ok flag, the
// reply's bytes and the final status.
struct RawCall {
  bool started = false, written = false, writes_done = false, read = false, finished = false;
  std::string reply;
  grpc::Status status;
};

RawCall CallRaw(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                const std::vector<std::string>& requests) {
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call =
      stub.PrepareCall(&context, method, &cq);
  // Waits for the operation tagged `n`; its ok flag.
  const auto await = [&cq](intptr_t n) {
    void* tag = nullptr;
    bool ok = false;
    EXPECT_TRUE(cq.Next(&tag, &ok));
    EXPECT_EQ(reinterpret_cast<intptr_t>(tag), n);
    return ok;
  };
  RawCall r;
  call->StartCall(reinterpret_cast<void*>(1));
  r.started = await(1);
  r.written = true;
  for (const std::string& bytes : requests) {
    grpc::Slice request(bytes);
    call->Write(grpc::ByteBuffer(&request, 1), reinterpret_cast<void*>(2));
    r.written = await(2) && r.written;
  }
  call->WritesDone(reinterpret_cast<void*>(3));
  r.writes_done = await(3);
  grpc::ByteBuffer reply;
  call->Read(&reply, reinterpret_cast<void*>(4));
  r.read = await(4);
  call->Finish(&r.status, reinterpret_cast<void*>(5));
  r.finished = await(5);
  cq.Shutdown();
  void* tag;
  bool ok;
  while (cq.Next(&tag, &ok)) {
  }
  if (r.read) {
    std::vector<grpc::Slice> slices;
    EXPECT_TRUE(reply.Dump(&slices).ok());
    for (const grpc::Slice& slice : slices) {
      r.reply.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
    }
  }
  return r;
}

RawCall CallRaw(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                const std::string& request_bytes) {
  return CallRaw(channel, method, std::vector<std::string>{request_bytes});
}

// Server reflection (grpc.reflection.v1alpha), spoken as raw bytes through
// a generic stub: the reflection protos are not installed, and defining
// them here would clash with the copy inside libgrpc++_reflection.
TEST_F(SessionsServiceTest, ReflectionListsTheServices) {
  // ServerReflectionRequest { list_services: "*" }: field 7, length 1.
  const RawCall c =
      CallRaw(channel_, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
              std::string("\x3a\x01*", 3));
  EXPECT_TRUE(c.started);
  EXPECT_TRUE(c.written);
  EXPECT_TRUE(c.writes_done);
  EXPECT_TRUE(c.read);
  EXPECT_TRUE(c.finished);
  EXPECT_THAT(c.status, GrpcOk());
  EXPECT_THAT(c.reply, AllOf(HasSubstr("dynsolid.Sessions"), HasSubstr("grpc.health.v1.Health")));
}

// Watch is served as a raw method (shared frame bytes): a request that is
// not a WatchRequest is refused with INVALID_ARGUMENT, and the server goes on.
TEST_F(SessionsServiceTest, UnparsableWatchRequestIsInvalidArgument) {
  // Field 1 (session) as a length-delimited value claiming 100 bytes: truncated.
  const RawCall c = CallRaw(channel_, "/dynsolid.Sessions/Watch", std::string("\x0a\x64\x01", 3));
  EXPECT_TRUE(c.started);
  EXPECT_FALSE(c.read);  // no frame
  EXPECT_TRUE(c.finished);
  EXPECT_THAT(c.status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                     HasSubstr("WatchRequest: not a valid message")));
  // The server still serves.
  Session s;
  EXPECT_THAT(CreateBuiltin("block3", &s, 0), GrpcOk());
}

// Bytes that are not a request, on every method of dynsolid.Sessions (unary
// and streaming alike): INVALID_ARGUMENT with a message naming the request
// type, never gRPC's bare UNIMPLEMENTED (unary) or an OK end (streams).
TEST_F(SessionsServiceTest, UnparsableRequestsAreInvalidArgumentOnEveryMethod) {
  const google::protobuf::ServiceDescriptor* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName("dynsolid.Sessions");
  ASSERT_NE(service, nullptr);
  ASSERT_EQ(service->method_count(), 15);
  // Tag 0 with wire type 7; a length-delimited field 1 claiming 100 bytes
  // of 1; a varint that never ends. None parses as any message.
  const std::vector<std::string> garbage = {std::string("\x07", 1), std::string("\x0a\x64\x01", 3),
                                            std::string(12, '\xff')};
  for (int i = 0; i < service->method_count(); ++i) {
    const google::protobuf::MethodDescriptor* m = service->method(i);
    const std::string path = absl::StrCat("/", service->full_name(), "/", m->name());
    for (const std::string& bytes : garbage) {
      const RawCall c = CallRaw(channel_, path, bytes);
      EXPECT_TRUE(c.finished) << path;
      EXPECT_FALSE(c.read) << path;
      EXPECT_THAT(c.status,
                  GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                               AllOf(HasSubstr(m->input_type()->name()),
                                     HasSubstr("not a valid message"))))
          << path << " with " << bytes.size() << " bytes";
    }
  }
  // On a stream, after a good request: the stream ends INVALID_ARGUMENT
  // (the good one's reply may or may not have gone out first, as with any
  // error that ends a stream).
  Session s;
  ASSERT_THAT(CreateBuiltin("block3", &s, 0), GrpcOk());
  CommandRequest good;
  good.mutable_session()->set_id(s.id());
  good.mutable_session()->set_token(s.token());
  good.set_client_id("garbage-test");
  good.set_seq(1);
  good.mutable_command()->mutable_pause();
  const RawCall c = CallRaw(channel_, "/dynsolid.Sessions/Commands",
                            {good.SerializeAsString(), std::string(12, '\xff')});
  if (c.read) {
    CommandReply reply;
    EXPECT_TRUE(reply.ParseFromString(c.reply));
    EXPECT_EQ(reply.seq(), 1);
  }
  EXPECT_THAT(c.status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                     HasSubstr("CommandRequest: not a valid message")));
  // The server still serves.
  Session again;
  EXPECT_THAT(CreateBuiltin("block3", &again, 0), GrpcOk());
}

// The cut-away: a horizontal plane through block3 gives triangles on it,
// with the field asked for; bad planes and fields are refused naming them.
TEST_F(SessionsServiceTest, SectionCutsTheSolidWhereThePlaneIs) {
  Session s;
  ASSERT_THAT(CreateBuiltin("block3", &s, 1), GrpcOk());
  auto section = [&](const std::string& field, double nz, SectionReply* reply) {
    SectionRequest r;
    r.mutable_session()->set_id(s.id());
    r.mutable_session()->set_token(s.token());
    r.mutable_point()->set_x(1.5);
    r.mutable_point()->set_y(1.5);
    r.mutable_point()->set_z(1.4);
    r.mutable_normal()->set_z(nz);
    r.set_field(field);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    return stub_->Section(&context, r, reply);
  };
  SectionReply cut;
  ASSERT_THAT(section("", 1, &cut), GrpcOk());
  EXPECT_EQ(cut.field(), "strain");
  EXPECT_EQ(cut.unit(), "1");
  EXPECT_GT(cut.cells_cut(), 0);
  ASSERT_GT(cut.values_size(), 0);
  EXPECT_EQ(cut.positions_size(), 3 * cut.values_size());
  for (int i = 2; i < cut.positions_size(); i += 3) EXPECT_NEAR(cut.positions(i), 1.4, 1e-5);
  SectionReply k;
  ASSERT_THAT(section("stiffness", 1, &k), GrpcOk());
  EXPECT_EQ(k.unit(), "Pa");
  EXPECT_GT(k.min(), 0);
  SectionReply bad;
  EXPECT_THAT(section("stress", 1, &bad),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("request.field: \"stress\"")));
  EXPECT_THAT(section("strain", 0, &bad),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("request.normal")));
}

// What a scene picker shows before anything is built: every built-in
// scene with its own description and its size.
TEST_F(SessionsServiceTest, ListScenesNamesEveryBuiltinSceneWithItsSize) {
  SceneList list;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  ASSERT_THAT(stub_->ListScenes(&context, google::protobuf::Empty(), &list), GrpcOk());
  std::vector<std::string> names;
  for (const SceneList::Entry& e : list.scenes()) names.push_back(e.name());
  EXPECT_EQ(names, scene::BuiltinSceneNames());
  for (const SceneList::Entry& e : list.scenes()) {
    EXPECT_FALSE(e.description().empty()) << e.name();
    EXPECT_GT(e.cells(), 0) << e.name();
    EXPECT_GT(e.control_cells(), 0) << e.name();
    if (e.name() == "block3") {
      EXPECT_EQ(e.control_cells(), 27);
      EXPECT_EQ(e.levels(), 2);
      EXPECT_EQ(e.cells(), 1728);  // what CreateSession builds (above)
      EXPECT_DOUBLE_EQ(e.size().x(), 3.0);
    }
    if (e.name() == "chair") {
      EXPECT_EQ(e.control_cells(), 76);
      EXPECT_EQ(e.cells(), 4864);
      EXPECT_THAT(e.description(), HasSubstr("chair"));
    }
  }
}

TEST_F(SessionsServiceTest, ShutdownWithOpenSessionsCompletesAndRefusesNewCalls) {
  Session s;
  ASSERT_THAT(CreateBuiltin("block3", &s, 1), GrpcOk());
  server_->Shutdown(absl::Seconds(5));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  Session got;
  SessionRef ref;
  ref.set_id(s.id());
  ref.set_token(s.token());
  EXPECT_THAT(stub_->GetSession(&context, ref, &got),
              GrpcStatusIs(grpc::StatusCode::UNAVAILABLE, _));
}

// Shutdown while one solid is being built and another waits for the build
// thread: every call still ends (no reactor is left unfinished), either
// with its session or UNAVAILABLE, and no session is opened after shutdown
// began.
TEST_F(SessionsServiceTest, ShutdownDuringCreatesFinishesEveryCall) {
  ServerOptions options = DefaultOptions();
  options.build_threads = 1;
  Start(options);
  std::vector<grpc::Status> results(3);
  std::vector<std::thread> clients;
  for (int i = 0; i < 3; ++i) {
    clients.emplace_back([this, i, &results] {
      Session s;
      results[i] = CreateBuiltin("block3", &s, i == 0 ? 2 : 1);
    });
  }
  // Give the calls time to reach the server (not needed for correctness:
  // any interleaving must end every call).
  absl::SleepFor(absl::Milliseconds(100));
  server_->Shutdown(absl::Seconds(30));
  for (std::thread& t : clients) t.join();
  for (const grpc::Status& status : results) {
    EXPECT_TRUE(status.ok() || status.error_code() == grpc::StatusCode::UNAVAILABLE)
        << static_cast<int>(status.error_code()) << ": " << status.error_message();
  }
}

TEST(ServerStartTest, BadOptionsAndUnbindableAddressesAreErrors) {
  ServerOptions options;
  options.listen = "no-port";
  EXPECT_EQ(Server::Start(options).status().code(), absl::StatusCode::kInvalidArgument);
  options.listen = "127.0.0.1:0";
  options.max_sessions = 0;
  EXPECT_EQ(Server::Start(options).status().code(), absl::StatusCode::kInvalidArgument);
  options.max_sessions = 1;
  options.stream_nice = 20;
  EXPECT_EQ(Server::Start(options).status(),
            absl::InvalidArgumentError("stream_nice must be in 0..19, got 20"));
  options.stream_nice = 10;
  options.sim_threads = 9;
  EXPECT_EQ(Server::Start(options).status(),
            absl::InvalidArgumentError("sim_threads must be in 0-8 (0: all cores but one), got 9"));
  options.sim_threads = -1;
  EXPECT_EQ(Server::Start(options).status().code(), absl::StatusCode::kInvalidArgument);
  options.sim_threads = 0;
  EXPECT_GE(SimThreads(0), 1);
  EXPECT_EQ(SimThreads(3), 3);

  // A port already taken by another server.
  ServerOptions first;
  first.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<Server>> a = Server::Start(first);
  ASSERT_TRUE(a.ok()) << a.status();
  ServerOptions second;
  second.listen = (*a)->address();
  absl::StatusOr<std::unique_ptr<Server>> b = Server::Start(second);
  EXPECT_EQ(b.status().code(), absl::StatusCode::kUnavailable) << b.status();
}

}  // namespace
}  // namespace dynsolid::server
