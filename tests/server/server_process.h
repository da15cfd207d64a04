// The real dynsolid-server binary as a child process, for the tests that
// start, kill and restart it (kill -9, a full data disk).
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::testing {

inline std::string ServerBinary() {
  const char* dir = std::getenv("DYNSOLID_BINARY_DIR");
  return absl::StrCat(dir != nullptr ? dir : "build/release", "/server/dynsolid-server");
}

// Reads `fd` up to its first newline (or two minutes without a byte).
inline std::string FirstLine(int fd) {
  std::string line;
  pollfd p{fd, POLLIN, 0};
  while (line.find('\n') == std::string::npos && ::poll(&p, 1, 120000) > 0) {
    char c;
    if (::read(fd, &c, 1) != 1) break;
    line.push_back(c);
  }
  return line;
}

// A dynsolid-server child process with `flags` (after --listen=127.0.0.1:0);
// its standard error is appended to `log`.
class ServerProcess {
 public:
  ServerProcess(const std::vector<std::string>& flags, const std::string& log) {
    int out[2];
    if (::pipe(out) != 0) return;
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      ::dup2(::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600), 2);
      ::close(out[0]);
      Exec(flags);
    }
    ::close(out[1]);
    // The first line: "listening on HOST:PORT".
    const std::string line = FirstLine(out[0]);
    ::close(out[0]);
    if (absl::StartsWith(line, "listening on ")) address_ = line.substr(13, line.size() - 14);
  }
  ~ServerProcess() {
    if (pid_ > 0) Signal(SIGTERM);
  }
  // Sends `signal` and reaps the process; returns its wait status.
  int Signal(int signal) {
    ::kill(pid_, signal);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return status;
  }
  const std::string& address() const { return address_; }
  std::shared_ptr<grpc::Channel> Channel() const {
    return grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  }
  std::unique_ptr<Sessions::Stub> Stub() const { return Sessions::NewStub(Channel()); }

 private:
  // In the child: becomes the server, or exits 127.
  [[noreturn]] static void Exec(const std::vector<std::string>& flags) {
    std::vector<std::string> args = {ServerBinary(), "--listen=127.0.0.1:0"};
    args.insert(args.end(), flags.begin(), flags.end());
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(args[0].c_str(), argv.data());
    ::_exit(127);
  }

  pid_t pid_ = -1;
  std::string address_;
};

}  // namespace dynsolid::testing
