#include "clients/haptic/loop_clock.h"

#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <string>

namespace dynsolid::haptic {
namespace {

inline void CpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

timespec ToTimespec(int64_t ns) {
  timespec ts;
  ts.tv_sec = ns / 1'000'000'000;
  ts.tv_nsec = ns % 1'000'000'000;
  return ts;
}

}  // namespace

int64_t MonotonicNs() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void DeadlineClock::Start() {
  start_ns_ = MonotonicNs();
  next_ = 1;
}

double DeadlineClock::Now() const { return (MonotonicNs() - start_ns_) * 1e-9; }

DeadlineClock::Tick DeadlineClock::Wait() {
  Tick t;
  int64_t now = MonotonicNs();
  int64_t deadline = start_ns_ + next_ * period_ns_;
  // More than a whole period late: give the missed deadlines up.
  if (now > deadline + period_ns_) {
    const int64_t behind = (now - deadline) / period_ns_;
    next_ += behind;
    t.skipped = behind;
    deadline = start_ns_ + next_ * period_ns_;
  }
  const int64_t wake = deadline - margin_ns_;
  if (now < wake) {
    const timespec ts = ToTimespec(wake);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
  while ((now = MonotonicNs()) < deadline) CpuRelax();
  t.index = next_;
  t.deadline = (deadline - start_ns_) * 1e-9;
  t.woke = (now - start_ns_) * 1e-9;
  ++next_;
  return t;
}

std::string TryRealtime(int priority) {
  std::string out;
  sched_param sp{};
  sp.sched_priority = priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  if (rc == 0) {
    out = "SCHED_FIFO priority " + std::to_string(priority);
  } else {
    out = std::string("SCHED_OTHER (SCHED_FIFO not allowed: ") + strerror(rc) +
          "; run with CAP_SYS_NICE or an rtprio limit for real-time priority)";
  }
  // MCL_CURRENT only: with MCL_FUTURE every later mapping (a gRPC thread's
  // 8 MB stack, an allocator arena) is populated while the process's
  // mmap lock is held, and the loop stalls behind it (measured: 5-15 ms
  // gaps). The loop itself does not allocate.
  if (mlockall(MCL_CURRENT) == 0) {
    out += ", memory locked";
  } else {
    out += std::string(", memory not locked (") + strerror(errno) + ")";
  }
  return out;
}

std::string TryPin(int cpu) {
  // Not checked against this thread's own mask: KeepOffCpu may have taken
  // `cpu` out of it on purpose. The kernel refuses a CPU outside the
  // process's cpuset (EINVAL).
  const long ncpu = sysconf(_SC_NPROCESSORS_CONF);
  if (cpu < 0 || cpu >= ncpu || cpu >= CPU_SETSIZE) {
    return "not pinned (CPU " + std::to_string(cpu) + " out of range: " + std::to_string(ncpu) +
           " CPUs)";
  }
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  const int rc = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
  if (rc != 0) {
    return "not pinned to CPU " + std::to_string(cpu) + " (" + strerror(rc) + ")";
  }
  return "pinned to CPU " + std::to_string(cpu);
}

std::string KeepOffCpu(int cpu) {
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (sched_getaffinity(0, sizeof(allowed), &allowed) != 0) {
    return std::string("other threads not moved (sched_getaffinity: ") + strerror(errno) + ")";
  }
  cpu_set_t others;
  CPU_ZERO(&others);
  std::string list;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (c == cpu || !CPU_ISSET(c, &allowed)) continue;
    CPU_SET(c, &others);
    list += (list.empty() ? "" : ",") + std::to_string(c);
  }
  if (list.empty()) return "other threads not moved (no other CPU)";
  const int rc = pthread_setaffinity_np(pthread_self(), sizeof(others), &others);
  if (rc != 0) return std::string("other threads not moved (") + strerror(rc) + ")";
  return "other threads on CPUs " + list;
}

}  // namespace dynsolid::haptic
