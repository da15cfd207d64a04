// The live session over loopback gRPC against an in-process server, across
// its server's life: sessions that survive a restart (journal and
// snapshots), a shutdown that finishes every stream, a journal that does
// not replay refused, and TLS. The rest of the live session is in
// live_test.cc.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "dynsolid/journal.pb.h"
#include "dynsolid/service.grpc.pb.h"
#include "live_client.h"
#include "live_fixture.h"
#include "server/journal.h"
#include "server/server.h"
#include "temp_dir.h"

namespace dynsolid::server {
namespace {

using ::dynsolid::testing::TempDir;
using ::testing::HasSubstr;

TEST_F(LiveTest, SessionsSurviveARestartWithTheirTokensStateAndAnswers) {
  TempDir dir("dynsolid_live");
  ServerOptions o = DataDirOptions(dir.path());
  o.loop.snapshot_every_steps = 7;  // snapshots and journal replay both
  Start(o);
  const Session s = Create("block3", 1, true);
  const Session ref = Create("block3", 1, true);
  // force, step 10, save, step 10: each step count is waited for, so the
  // commands apply at steps 0, 0, 10, 10.
  Command save;
  save.mutable_save();
  const std::vector<std::pair<Command, int64_t>> script = {
      {ForceCommand(1.5, 1.5, 3, 1e4, 0, 0), 0}, {StepCommand(10), 10}, {save, 10},
      {StepCommand(10), 20}};
  std::vector<CommandReply> replies;
  {
    CommandStream c(*stub_, s, "persist");
    for (size_t i = 0; i < script.size(); ++i) {
      replies.push_back(c.Send(i + 1, script[i].first));
      InspectAt(*stub_, s, script[i].second, false, false);
    }
    c.Finish();
  }
  EXPECT_EQ(replies[2].code(), 0) << replies[2].message();
  EXPECT_EQ(replies[2].saved().step(), 10);
  EXPECT_GT(replies[2].saved().bytes(), 0);
  const InspectReply before = InspectAt(*stub_, s, 20);
  const SessionStats stats = StatsOf(*stub_, s);
  EXPECT_EQ(stats.journal_records(), 4);
  EXPECT_GE(stats.snapshots(), 2);

  server_->Shutdown(absl::Seconds(2));
  Start(o);  // same data dir
  EXPECT_EQ(server_->recovered_sessions(), 2);
  const InspectReply after = InspectAt(*stub_, s, 0);
  EXPECT_EQ(after.step(), 20);
  EXPECT_TRUE(after.paused());
  EXPECT_TRUE(BitIdentical(after.control_positions(), before.control_positions()));
  EXPECT_TRUE(BitIdentical(after.surface_positions(), before.surface_positions()));
  // The answers survived: a resend is a duplicate with the original step.
  CommandStream c(*stub_, s, "persist");
  const CommandReply dup = c.Send(3, save);
  EXPECT_TRUE(dup.duplicate());
  EXPECT_EQ(dup.applied_step(), 10);
  EXPECT_EQ(dup.saved().step(), 10);
  // And it continues exactly like a session that never restarted.
  ASSERT_EQ(c.Send(5, StepCommand(15)).code(), 0);
  CommandStream cr(*stub_, ref, "persist");
  for (size_t i = 0; i < script.size(); ++i) {
    if (script[i].first.has_save()) continue;
    cr.Send(i + 1, script[i].first);
    InspectAt(*stub_, ref, script[i].second, false, false);
  }
  cr.Send(5, StepCommand(15));
  const InspectReply x = InspectAt(*stub_, s, 35), y = InspectAt(*stub_, ref, 35);
  EXPECT_EQ(x.step(), 35);
  EXPECT_TRUE(BitIdentical(x.control_positions(), y.control_positions()));
  // A wrong token is still refused after the restart.
  Session wrong = s;
  wrong.set_token(std::string(32, 'f'));
  grpc::Status status;
  InspectAt(*stub_, wrong, 0, false, false, &status);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  // Closing deletes the session's directory.
  grpc::ClientContext context;
  google::protobuf::Empty e;
  ASSERT_TRUE(stub_->CloseSession(&context, RefOf(s), &e).ok());
  EXPECT_FALSE(ReadWholeFile(dir.path() + "/sessions/" + s.id() + "/manifest.binpb").ok());
}

TEST_F(LiveTest, ShutdownFinishesEveryStreamWithAStatusAndWritesALastSnapshot) {
  TempDir dir("dynsolid_live");
  ServerOptions o = DataDirOptions(dir.path());
  Start(o);
  const Session s = Create("block3", 1, /*paused=*/true);
  grpc::ClientContext wc;
  auto reader = WatchOf(s, &wc);
  ASSERT_TRUE(ReadsAFrame(*reader));
  CommandStream c(*stub_, s, "shutdown");
  ASSERT_EQ(c.Send(1, StepCommand(12)).code(), 0);
  InspectAt(*stub_, s, 12, false, false);
  // An inspection waiting for a step the paused session never reaches.
  grpc::Status waiting;
  std::thread inspect([&] { InspectAt(*stub_, s, 1000, false, false, &waiting); });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));

  server_->Shutdown(absl::Seconds(5));
  inspect.join();
  EXPECT_EQ(waiting.error_code(), grpc::StatusCode::UNAVAILABLE);
  ExpectStreamsEndUnavailable(*reader, c, "shutting down");

  // The last snapshot is at step 12: a restart replays nothing.
  Start(o);
  const SessionStats st = StatsOf(*stub_, s);
  EXPECT_EQ(st.step(), 12);
  EXPECT_EQ(st.last_snapshot_step(), 12);
}

TEST_F(LiveTest, AJournalThatDoesNotReplayToItsOutcomesIsNotOpened) {
  TempDir dir("dynsolid_live");
  ServerOptions o = DataDirOptions(dir.path());
  Start(o);
  const Session s = Create("block3", 1, /*paused=*/true);
  {
    CommandStream c(*stub_, s, "tamper");
    ASSERT_EQ(c.Send(1, ForceCommand(1.5, 1.5, 3, 1e4, 0, 0)).code(), 0);
    c.Finish();
  }
  server_->Shutdown(absl::Seconds(2));
  server_.reset();
  // Rewrite the record (with a valid CRC) as if the command had been
  // rejected, and drop the snapshot so the journal is replayed.
  const std::string sdir = dir.path() + "/sessions/" + s.id();
  absl::StatusOr<JournalContents> journal = ReadJournal(sdir + "/journal", 0);
  ASSERT_TRUE(journal.ok());
  ASSERT_EQ(journal->records.size(), 1u);
  persist::JournalRecord record;
  ASSERT_TRUE(record.ParseFromString(journal->records[0]));
  record.mutable_reply()->set_code(3);
  ASSERT_TRUE(WriteFileAtomically(sdir, "journal", FrameRecord(record.SerializeAsString())).ok());
  ASSERT_EQ(std::remove((sdir + "/snapshot.binpb").c_str()), 0);
  Start(o);
  EXPECT_EQ(server_->recovered_sessions(), 0);
  grpc::Status status;
  InspectAt(*stub_, s, 0, false, false, &status);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  // Left on disk, untouched, for a person to look at.
  EXPECT_TRUE(ReadWholeFile(sdir + "/manifest.binpb").ok());
}

TEST_F(LiveTest, TlsServesClientsThatTrustItsCertificateOnly) {
  TempDir dir("dynsolid_live");
  const std::string cert = dir.path() + "/cert.pem", key = dir.path() + "/key.pem";
  const std::string cmd = absl::StrCat(
      "openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=localhost "
      "-addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout '", key, "' -out '", cert,
      "' >/dev/null 2>&1");
  ASSERT_EQ(std::system(cmd.c_str()), 0) << "openssl could not make a certificate";
  ServerOptions o = Options();
  o.tls_cert_file = cert;
  o.tls_key_file = key;
  Start(o);
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = *ReadWholeFile(cert);
  grpc::ChannelArguments args;
  args.SetSslTargetNameOverride("localhost");
  auto tls = Sessions::NewStub(grpc::CreateCustomChannel(
      absl::StrCat("localhost:", server_->port()), grpc::SslCredentials(ssl), args));
  const CreateSessionRequest r = PausedBlock3Request();
  Session s;
  {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    const grpc::Status st = tls->CreateSession(&context, r, &s);
    ASSERT_TRUE(st.ok()) << st.error_message();
  }
  CommandStream c(*tls, s, "tls");
  EXPECT_EQ(c.Send(1, StepCommand(2)).code(), 0);
  EXPECT_EQ(InspectAt(*tls, s, 2).step(), 2);
  // A plaintext client cannot talk to it.
  {
    grpc::ClientContext context;
    context.set_deadline(Deadline(5));
    Session ignored;
    EXPECT_FALSE(stub_->CreateSession(&context, r, &ignored).ok());
  }
  // Nor a TLS client that does not trust the certificate.
  {
    grpc::SslCredentialsOptions other;
    other.pem_root_certs = "";
    auto untrusting = Sessions::NewStub(grpc::CreateCustomChannel(
        absl::StrCat("localhost:", server_->port()), grpc::SslCredentials(other), args));
    grpc::ClientContext context;
    context.set_deadline(Deadline(5));
    Session ignored;
    EXPECT_FALSE(untrusting->CreateSession(&context, r, &ignored).ok());
  }
  // Both TLS files or neither.
  ServerOptions half = Options();
  half.tls_cert_file = cert;
  EXPECT_EQ(Server::Start(half).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace dynsolid::server
