#include "server/log.h"

#include <memory>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

namespace dynsolid::server {

spdlog::logger& ServerLog() {
  static const std::shared_ptr<spdlog::logger> log = [] {
    std::shared_ptr<spdlog::logger> l = spdlog::get("server");
    return l != nullptr ? l : spdlog::stderr_color_mt("server");
  }();
  return *log;
}

}  // namespace dynsolid::server
