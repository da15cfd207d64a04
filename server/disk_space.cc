#include "server/disk_space.h"

#include <sys/statvfs.h>

#include <cerrno>

#include "absl/strings/str_cat.h"
#include "server/log.h"

namespace dynsolid::server {

bool IsNoSpace(int error_number) { return error_number == ENOSPC || error_number == EDQUOT; }

void DiskSpace::SetListener(std::function<void(bool full)> listener) {
  absl::MutexLock lock(&mu_);
  listener_ = std::move(listener);
}

void DiskSpace::ReportFull(absl::string_view what) {
  if (!full()) ServerLog().warn("data disk {} is full: {}", dir_, std::string(what));
  Set(true);
}

int64_t DiskSpace::Check() {
  struct statvfs st;
  if (::statvfs(dir_.c_str(), &st) != 0) return -1;
  const int64_t available = static_cast<int64_t>(st.f_bavail) * static_cast<int64_t>(st.f_frsize);
  const bool now_full = available < min_free_bytes_;
  if (now_full != full()) {
    if (now_full) {
      ServerLog().warn("data disk {} is full: {} bytes available, --min_free_disk_bytes {}", dir_,
                       available, min_free_bytes_);
    } else {
      ServerLog().info("data disk {} has room again: {} bytes available", dir_, available);
    }
  }
  Set(now_full);
  return available;
}

absl::Status DiskSpace::CheckNewSession() const {
  if (!full()) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      "no space left on the data disk (", dir_, "; --min_free_disk_bytes ", min_free_bytes_,
      "): new sessions are refused until space returns"));
}

void DiskSpace::Set(bool full) {
  full_.store(full, std::memory_order_release);
  // The listener runs under mu_, so that two threads changing the state
  // at once report it in the order it changed.
  absl::MutexLock lock(&mu_);
  if (reported_ == full) return;
  reported_ = full;
  if (listener_) listener_(full);
}

}  // namespace dynsolid::server
