// The server's spdlog logger ("server", to stderr). Never log tokens.
#pragma once

#include <spdlog/logger.h>

namespace dynsolid::server {

spdlog::logger& ServerLog();

}  // namespace dynsolid::server
