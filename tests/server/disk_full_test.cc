// A full data disk: the real dynsolid-server binary with its
// --data_dir on a small tmpfs that the test fills.
//
//  - A command that cannot be journaled is refused (RESOURCE_EXHAUSTED, "no
//    space left on the data disk ...") and not applied: the session's step
//    never counts it, watchers never see it, and a server restarted on the
//    directory (after kill -9) holds exactly the acknowledged commands.
//  - While the disk is full, health says NOT_SERVING and new sessions are
//    refused; both recover once space returns.
//  - A creation that fails for want of space leaves no directory behind.
//
// An unprivileged test cannot mount a tmpfs, so main() first enters a user
// and mount namespace of its own (as `unshare -Urm` does; the server
// processes it starts inherit it). Where that is not allowed the tests are
// skipped, saying why.
#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "dynsolid/service.grpc.pb.h"
#include "health.grpc.pb.h"
#include "live_client.h"
#include "server_process.h"

namespace dynsolid {
namespace {

using ::testing::HasSubstr;
using testing::CommandStream;
using testing::CreatePausedBlock3;
using testing::Deadline;
using testing::ForceCommand;
using testing::InspectAt;
using testing::ServerProcess;
using testing::StepCommand;

// Why the namespace could not be entered (empty: it was).
std::string g_no_namespace;

bool WriteProcFile(const std::string& path, const std::string& text) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  ::close(fd);
  return ok;
}

// unshare -Urm: a user namespace mapping this user to root, and a private
// mount namespace. Must run before any thread starts.
std::string EnterUserAndMountNamespace() {
  const uid_t uid = ::getuid();
  const gid_t gid = ::getgid();
  if (::unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0) {
    return absl::StrCat("unshare(CLONE_NEWUSER | CLONE_NEWNS): ", std::strerror(errno));
  }
  if (!WriteProcFile("/proc/self/setgroups", "deny") ||
      !WriteProcFile("/proc/self/uid_map", absl::StrCat("0 ", uid, " 1")) ||
      !WriteProcFile("/proc/self/gid_map", absl::StrCat("0 ", gid, " 1"))) {
    return absl::StrCat("cannot write the namespace's id maps: ", std::strerror(errno));
  }
  if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0) {
    return absl::StrCat("cannot make / private: ", std::strerror(errno));
  }
  return "";
}

// A tmpfs of `bytes` mounted on a fresh directory (inside the namespace).
class SmallDisk {
 public:
  explicit SmallDisk(int64_t bytes) {
    std::string t = ::testing::TempDir() + "dynsolid_diskfull_XXXXXX";
    root_ = ::mkdtemp(t.data());
    mount_ = root_ + "/disk";
    ::mkdir(mount_.c_str(), 0700);
    mounted_ = ::mount("tmpfs", mount_.c_str(), "tmpfs", 0,
                       absl::StrCat("size=", bytes, ",mode=0700").c_str()) == 0;
    if (!mounted_) error_ = std::strerror(errno);
  }
  ~SmallDisk() {
    if (mounted_) ::umount2(mount_.c_str(), MNT_DETACH);
    if (::testing::Test::HasFailure()) {
      std::cerr << "kept " << root_ << " (the server's log)\n";
    } else {
      std::system(absl::StrCat("rm -rf '", root_, "'").c_str());
    }
  }
  bool mounted() const { return mounted_; }
  const std::string& error() const { return error_; }
  const std::string& path() const { return mount_; }   // on the tmpfs
  std::string log() const { return root_ + "/server.log"; }  // off it

  // Writes a filler file until the tmpfs is full. Returns its bytes.
  int64_t Fill() {
    const std::string filler = mount_ + "/filler";
    const int fd = ::open(filler.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    if (fd < 0) return -1;
    int64_t total = 0;
    std::string chunk(64 << 10, 'x');
    for (size_t size : {size_t{64} << 10, size_t{4} << 10, size_t{512}, size_t{1}}) {
      for (;;) {
        const ssize_t n = ::write(fd, chunk.data(), size);
        if (n <= 0) break;
        total += n;
      }
    }
    ::close(fd);
    return total;
  }
  void Free() { ::unlink((mount_ + "/filler").c_str()); }

 private:
  std::string root_, mount_, error_;
  bool mounted_ = false;
};

std::vector<std::string> SessionDirs(const std::string& data_dir) {
  std::vector<std::string> out;
  const std::string root = data_dir + "/sessions";
  if (DIR* d = ::opendir(root.c_str())) {
    while (const dirent* e = ::readdir(d)) {
      const std::string name = e->d_name;
      if (name != "." && name != "..") out.push_back(name);
    }
    ::closedir(d);
  }
  return out;
}

grpc::health::v1::HealthCheckResponse::ServingStatus Health(grpc::Channel& channel) {
  auto stub = grpc::health::v1::Health::NewStub(
      std::shared_ptr<grpc::Channel>(&channel, [](grpc::Channel*) {}));
  grpc::ClientContext context;
  context.set_deadline(Deadline(10));
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status s = stub->Check(&context, grpc::health::v1::HealthCheckRequest(), &response);
  return s.ok() ? response.status() : grpc::health::v1::HealthCheckResponse::UNKNOWN;
}

// Polls health until it says `want` (the server checks its disk every
// 250 ms); false after a minute.
bool HealthBecomes(grpc::Channel& channel,
                   grpc::health::v1::HealthCheckResponse::ServingStatus want) {
  for (int i = 0; i < 600; ++i) {
    if (Health(channel) == want) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

// Reads a Watch stream on a thread of its own: the highest step of any
// frame it got.
class Watcher {
 public:
  Watcher(Sessions::Stub& stub, const Session& s) {
    WatchRequest r;
    *r.mutable_session() = testing::RefOf(s);
    r.set_rate_hz(240);
    reader_ = stub.Watch(&context_, r);
    thread_ = std::thread([this] {
      Frame f;
      while (reader_->Read(&f)) {
        if (f.step() > max_step_.load()) max_step_.store(f.step());
      }
    });
  }
  ~Watcher() {
    context_.TryCancel();
    thread_.join();
    reader_->Finish();
  }
  int64_t max_step() const { return max_step_.load(); }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReader<Frame>> reader_;
  std::atomic<int64_t> max_step_{-1};
  std::thread thread_;
};

std::vector<uint64_t> LoggedSeqs(Sessions::Stub& stub, const Session& s, const std::string& client) {
  grpc::ClientContext context;
  context.set_deadline(Deadline());
  CommandLogRequest r;
  *r.mutable_session() = testing::RefOf(s);
  r.set_client_id(client);
  CommandLog log;
  const grpc::Status status = stub.GetCommandLog(&context, r, &log);
  EXPECT_TRUE(status.ok()) << status.error_message();
  std::vector<uint64_t> seqs;
  for (const CommandLogEntry& e : log.entries()) {
    EXPECT_EQ(e.code(), 0) << "seq " << e.seq();
    seqs.push_back(e.seq());
  }
  return seqs;
}

TEST(DiskFullTest, UnjournaledCommandsAreRefusedNotAppliedAndARestartHasExactlyTheAcknowledged) {
  if (!g_no_namespace.empty()) GTEST_SKIP() << "no user+mount namespace: " << g_no_namespace;
  SmallDisk disk(4 << 20);
  ASSERT_TRUE(disk.mounted()) << "mount tmpfs: " << disk.error();
  const std::string data = disk.path() + "/data";
  // (gRPC's threads at the simulation's priority: on a busy machine
  // SCHED_IDLE ones answer hundreds of commands too slowly.)
  const std::vector<std::string> flags = {"--data_dir=" + data, "--min_free_disk_bytes=65536",
                                          "--snapshot_every_steps=1000000", "--stream_idle=false",
                                          "--stream_nice=0"};
  std::vector<uint64_t> acknowledged;
  int64_t expected_step = 0;
  Session s;
  {
    ServerProcess server(flags, disk.log());
    ASSERT_FALSE(server.address().empty()) << "the server did not start; see " << disk.log();
    std::shared_ptr<grpc::Channel> channel = server.Channel();
    auto stub = Sessions::NewStub(channel);
    ASSERT_TRUE(CreatePausedBlock3(*stub, &s).ok());
    EXPECT_EQ(Health(*channel), grpc::health::v1::HealthCheckResponse::SERVING);
    Watcher watcher(*stub, s);
    CommandStream c(*stub, s, "disk", /*deadline_seconds=*/1200);
    uint64_t seq = 1;
    ASSERT_EQ(c.Send(seq, ForceCommand(1.5, 1.5, 3, 0, 5e3, 0)).code(), 0);
    acknowledged.push_back(seq++);

    ASSERT_GT(disk.Fill(), 0);
    // Each Step(1) that is acknowledged steps the session once; journal
    // space reserved earlier lets the first few through, then they are
    // refused.
    CommandReply refused;
    for (int i = 0; i < 20000; ++i) {
      const CommandReply r = c.Send(seq, StepCommand(1));
      if (r.code() != 0) {
        refused = r;
        break;
      }
      acknowledged.push_back(seq++);
      ++expected_step;
    }
    ASSERT_EQ(refused.code(), static_cast<int>(grpc::StatusCode::RESOURCE_EXHAUSTED))
        << refused.message();
    std::cout << "disk full: " << expected_step
              << " commands acknowledged into the journal's reserved space, then refused: "
              << refused.message() << "\n";
    EXPECT_THAT(refused.message(), HasSubstr("no space left on the data disk"));
    EXPECT_THAT(refused.message(), HasSubstr("not applied"));
    EXPECT_EQ(refused.applied_step(), -1);
    // More of them, while full: refused too.
    for (int i = 0; i < 3; ++i) {
      EXPECT_EQ(c.Send(seq + 1 + i, StepCommand(5)).code(),
                static_cast<int>(grpc::StatusCode::RESOURCE_EXHAUSTED));
    }
    // Not applied: the session stepped exactly the acknowledged steps and
    // has none left to run.
    InspectReply at = InspectAt(*stub, s, expected_step, false, false);
    EXPECT_EQ(at.step(), expected_step);
    EXPECT_EQ(at.steps_remaining(), 0);
    EXPECT_TRUE(at.paused());
    // While full: NOT_SERVING, no new session, and no stray directory.
    EXPECT_TRUE(HealthBecomes(*channel, grpc::health::v1::HealthCheckResponse::NOT_SERVING));
    Session other;
    const grpc::Status created = CreatePausedBlock3(*stub, &other);
    EXPECT_EQ(created.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_THAT(created.error_message(), HasSubstr("no space left on the data disk"));
    EXPECT_EQ(SessionDirs(data).size(), 1u);

    // Space returns: SERVING again, and the refused seq goes through when
    // sent again.
    disk.Free();
    EXPECT_TRUE(HealthBecomes(*channel, grpc::health::v1::HealthCheckResponse::SERVING));
    ASSERT_EQ(c.Send(seq, StepCommand(2)).code(), 0);
    acknowledged.push_back(seq++);
    expected_step += 2;
    at = InspectAt(*stub, s, expected_step, false, false);
    EXPECT_EQ(at.step(), expected_step);
    EXPECT_EQ(at.steps_remaining(), 0);
    // The watcher never saw a step the acknowledged commands did not make.
    EXPECT_LE(watcher.max_step(), expected_step);
    EXPECT_EQ(LoggedSeqs(*stub, s, "disk"), acknowledged);
    // A new session opens again.
    EXPECT_TRUE(CreatePausedBlock3(*stub, &other).ok());
    server.Signal(SIGKILL);
  }
  // Restarted on the same directory: exactly the acknowledged commands.
  ServerProcess server(flags, disk.log());
  ASSERT_FALSE(server.address().empty()) << "the server did not restart; see " << disk.log();
  auto stub = Sessions::NewStub(server.Channel());
  const InspectReply at = InspectAt(*stub, s, 0, false, false);
  EXPECT_EQ(at.step(), expected_step);
  EXPECT_EQ(at.steps_remaining(), 0);
  EXPECT_EQ(LoggedSeqs(*stub, s, "disk"), acknowledged);
}

TEST(DiskFullTest, ACreationThatCannotWriteLeavesNoDirectory) {
  if (!g_no_namespace.empty()) GTEST_SKIP() << "no user+mount namespace: " << g_no_namespace;
  SmallDisk disk(1 << 20);
  ASSERT_TRUE(disk.mounted()) << "mount tmpfs: " << disk.error();
  const std::string data = disk.path() + "/data";
  // --min_free_disk_bytes=0: the server does not see the disk full before
  // it writes, so the creation itself meets ENOSPC.
  ServerProcess server({"--data_dir=" + data, "--min_free_disk_bytes=0", "--stream_idle=false"},
                       disk.log());
  ASSERT_FALSE(server.address().empty()) << "the server did not start; see " << disk.log();
  auto stub = Sessions::NewStub(server.Channel());
  ASSERT_GT(disk.Fill(), 0);
  Session s;
  const grpc::Status created = CreatePausedBlock3(*stub, &s);
  EXPECT_EQ(created.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << created.error_message();
  EXPECT_THAT(created.error_message(), HasSubstr("no space left on the data disk"));
  EXPECT_THAT(SessionDirs(data), ::testing::IsEmpty());
  disk.Free();
  EXPECT_TRUE(HealthBecomes(*server.Channel(), grpc::health::v1::HealthCheckResponse::SERVING));
  const grpc::Status again = CreatePausedBlock3(*stub, &s);
  EXPECT_TRUE(again.ok()) << again.error_message();
  EXPECT_EQ(SessionDirs(data).size(), 1u);
}

}  // namespace
}  // namespace dynsolid

int main(int argc, char** argv) {
  // Before gtest or gRPC start a thread: unshare(CLONE_NEWUSER) needs a
  // single-threaded process.
  dynsolid::g_no_namespace = dynsolid::EnterUserAndMountNamespace();
  ::testing::InitGoogleMock(&argc, argv);
  return RUN_ALL_TESTS();
}
