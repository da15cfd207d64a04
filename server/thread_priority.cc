#include "server/thread_priority.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "absl/strings/str_cat.h"

namespace dynsolid::server {
namespace {

id_t ThisThreadId() { return static_cast<id_t>(::syscall(SYS_gettid)); }

}  // namespace

absl::Status MakeThisThreadIdle() {
  sched_param param{};
  param.sched_priority = 0;
  if (const int e = ::pthread_setschedparam(::pthread_self(), SCHED_IDLE, &param); e != 0) {
    return absl::InternalError(absl::StrCat("SCHED_IDLE: ", std::strerror(e)));
  }
  return absl::OkStatus();
}

bool ThisThreadIsIdle() {
  int policy = 0;
  sched_param param{};
  return ::pthread_getschedparam(::pthread_self(), &policy, &param) == 0 && policy == SCHED_IDLE;
}

int ThisThreadNice() {
  errno = 0;
  return ::getpriority(PRIO_PROCESS, ThisThreadId());
}

absl::Status LowerThisThreadPriority(int delta) {
  if (delta < 0 || delta > 19) {
    return absl::InvalidArgumentError(
        absl::StrCat("a thread's nice value can be raised by 0..19, got ", delta));
  }
  if (delta == 0) return absl::OkStatus();
  const int now = ThisThreadNice();
  const int target = std::min(19, now + delta);
  if (::setpriority(PRIO_PROCESS, ThisThreadId(), target) != 0) {
    return absl::InternalError(
        absl::StrCat("setpriority(nice ", target, "): ", std::strerror(errno)));
  }
  return absl::OkStatus();
}

void NameThisThread(const char* name) {
  char shortened[16] = {};
  std::strncpy(shortened, name, sizeof(shortened) - 1);
  ::pthread_setname_np(::pthread_self(), shortened);
}

ThreadCpu ThisThreadCpu() {
  // "on-CPU ns, run-queue wait ns, timeslices".
  std::ifstream f("/proc/thread-self/schedstat");
  double run_ns = 0, wait_ns = 0;
  ThreadCpu t;
  if (f >> run_ns >> wait_ns) {
    t.cpu_ms = run_ns * 1e-6;
    t.wait_ms = wait_ns * 1e-6;
  }
  return t;
}

}  // namespace dynsolid::server
