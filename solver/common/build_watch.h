// A watch over the builds a thread runs: whoever asks for a build (the
// server, for a session's solid) installs a check, and the build calls
// CheckBuildWatch between its phases and stops with the check's status
// when it fails, freeing what it made. The solver does not know what the
// check measures (the server compares its own resident memory with the
// session's estimate, server/solid_builder.cc).
//
// The watch belongs to the installing thread (thread_local): the phases'
// boundaries are on the thread that called the build, its worker pools
// never check. Without a watch CheckBuildWatch is OK.
#pragma once

#include <functional>
#include <string_view>

#include "absl/status/status.h"

namespace dynsolid::common {

// Called with the phase just finished ("subdivision", "layout", "model and
// mass", ...); a non-OK status stops the build with that status.
using BuildCheck = std::function<absl::Status(std::string_view phase)>;

// Installs `check` for this thread's builds until destroyed (the previous
// one, if any, is back then).
class ScopedBuildWatch {
 public:
  explicit ScopedBuildWatch(BuildCheck check);
  ~ScopedBuildWatch();
  ScopedBuildWatch(const ScopedBuildWatch&) = delete;
  ScopedBuildWatch& operator=(const ScopedBuildWatch&) = delete;

 private:
  BuildCheck check_;
  const BuildCheck* previous_;
};

// The installed check's verdict on `phase` (OK without one).
absl::Status CheckBuildWatch(std::string_view phase);

}  // namespace dynsolid::common
