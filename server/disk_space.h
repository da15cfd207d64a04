// Whether the data disk (--data_dir) has room, as the server sees it.
//
// It turns "full" when a session cannot reserve journal space or a write
// fails with ENOSPC/EDQUOT (ReportFull), or when a periodic Check finds
// fewer than min_free_bytes available (statvfs); it turns back when a Check
// finds at least that many. While full, new sessions are refused and the
// server's health says NOT_SERVING (server.cc); sessions already open go
// on, and a command that cannot be journaled is refused, not applied
// (session_loop.cc).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"

namespace dynsolid::server {

class DiskSpace {
 public:
  DiskSpace(std::string dir, int64_t min_free_bytes)
      : dir_(std::move(dir)), min_free_bytes_(min_free_bytes) {}

  const std::string& dir() const { return dir_; }
  int64_t min_free_bytes() const { return min_free_bytes_; }
  bool full() const { return full_.load(std::memory_order_acquire); }

  // Called with the new state whenever it changes (from the thread that
  // changed it, under this object's lock: it must not call back here).
  void SetListener(std::function<void(bool full)> listener);

  // A write or a reservation failed for want of space: full at once.
  void ReportFull(absl::string_view what);
  // statvfs of dir: full below min_free_bytes available, else not full.
  // Returns the bytes available to the server (-1 when statvfs fails, which
  // changes nothing).
  int64_t Check();

  // ResourceExhausted "no space left on the data disk ..." for a new
  // session while full; OK otherwise.
  absl::Status CheckNewSession() const;

 private:
  void Set(bool full);

  const std::string dir_;
  const int64_t min_free_bytes_;
  std::atomic<bool> full_{false};
  absl::Mutex mu_;
  std::function<void(bool)> listener_ ABSL_GUARDED_BY(mu_);
  bool reported_ ABSL_GUARDED_BY(mu_) = false;  // the state the listener last got
};

// True for the errnos that mean "no space" (ENOSPC, EDQUOT).
bool IsNoSpace(int error_number);

}  // namespace dynsolid::server
