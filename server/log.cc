#include "server/log.h"

#include <memory>
#include <string>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

namespace dynsolid::server {
namespace {

// Each logger is made once (function-local statics are thread-safe), or
// taken from spdlog's registry if the program made it first.
std::shared_ptr<spdlog::logger> Make(const std::string& name) {
  std::shared_ptr<spdlog::logger> l = spdlog::get(name);
  return l != nullptr ? l : spdlog::stderr_color_mt(name);
}

}  // namespace

spdlog::logger& ServerLog() {
  static const std::shared_ptr<spdlog::logger> log = Make("server");
  return *log;
}
spdlog::logger& SessionLog() {
  static const std::shared_ptr<spdlog::logger> log = Make("session");
  return *log;
}
spdlog::logger& WatchLog() {
  static const std::shared_ptr<spdlog::logger> log = Make("watch");
  return *log;
}
spdlog::logger& JournalLog() {
  static const std::shared_ptr<spdlog::logger> log = Make("journal");
  return *log;
}

}  // namespace dynsolid::server
