// A dynsolid-server started by the load tester: its own --data_dir, a free
// loopback port (kept across restarts), SIGKILL and restart, CPU and RSS
// from /proc.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

#include "absl/status/status.h"

namespace dynsolid::load {

class ServerProcess {
 public:
  ServerProcess(std::string binary, std::string data_dir, std::vector<std::string> args)
      : binary_(std::move(binary)), data_dir_(std::move(data_dir)), args_(std::move(args)) {}
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // Starts it (on 127.0.0.1:0 the first time, then on the same port) and
  // waits for its "listening on ADDR" line.
  absl::Status Start();
  // SIGKILL, reaped.
  void Kill();
  // SIGTERM; its exit status (0: a clean stop).
  int Stop();
  const std::string& address() const { return address_; }
  pid_t pid() const { return pid_; }
  // Total CPU seconds (user + system) and resident kB, from /proc.
  bool Sample(double* cpu_seconds, long* rss_kb) const;

 private:
  std::string binary_, data_dir_;
  std::vector<std::string> args_;
  std::string address_;
  pid_t pid_ = -1;
  std::string log_path_;
};

}  // namespace dynsolid::load
