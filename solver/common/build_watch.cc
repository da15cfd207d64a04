#include "solver/common/build_watch.h"

#include <utility>

namespace dynsolid::common {
namespace {

thread_local const BuildCheck* installed = nullptr;

}  // namespace

ScopedBuildWatch::ScopedBuildWatch(BuildCheck check)
    : check_(std::move(check)), previous_(installed) {
  installed = &check_;
}

ScopedBuildWatch::~ScopedBuildWatch() { installed = previous_; }

absl::Status CheckBuildWatch(std::string_view phase) {
  if (installed == nullptr || !*installed) return absl::OkStatus();
  return (*installed)(phase);
}

}  // namespace dynsolid::common
