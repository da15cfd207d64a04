// The server's spdlog loggers, one per component, all to stderr:
//   "server"   start, shutdown, session creation and closing
//   "session"  a session's loop: commands, steps that fail, recovery
//   "watch"    watchers joining and leaving
//   "journal"  persistence: journal and snapshot writes, failures
// Never log tokens.
#pragma once

#include <spdlog/logger.h>

namespace dynsolid::server {

spdlog::logger& ServerLog();
spdlog::logger& SessionLog();
spdlog::logger& WatchLog();
spdlog::logger& JournalLog();

}  // namespace dynsolid::server
