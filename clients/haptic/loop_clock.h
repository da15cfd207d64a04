// The bridge's 1 kHz clock: absolute deadlines on CLOCK_MONOTONIC (tick k
// is due at start + k T, so errors never accumulate), reached by sleeping
// to `spin_margin` before the deadline (clock_nanosleep TIMER_ABSTIME) and
// spinning the rest. A tick that wakes more than a whole period late skips
// the deadlines it missed (counted) instead of running a burst.
#pragma once

#include <cstdint>
#include <string>

namespace dynsolid::haptic {

class DeadlineClock {
 public:
  // period and spin_margin in seconds.
  explicit DeadlineClock(double period, double spin_margin = 200e-6)
      : period_ns_(static_cast<int64_t>(period * 1e9)),
        margin_ns_(static_cast<int64_t>(spin_margin * 1e9)) {}

  struct Tick {
    int64_t index = 0;    // deadline number since Start
    double deadline = 0;  // seconds since Start
    double woke = 0;      // when Wait returned, seconds since Start
    int64_t skipped = 0;  // deadlines given up before this one
  };
  // Anchors the clock: the first deadline is one period from now.
  void Start();
  // Waits for the next deadline.
  Tick Wait();
  // Seconds since Start.
  double Now() const;
  double period() const { return period_ns_ * 1e-9; }
  // MonotonicNs() at Start (CLOCK_MONOTONIC: std::chrono::steady_clock's
  // epoch on Linux).
  int64_t start_ns() const { return start_ns_; }

 private:
  const int64_t period_ns_, margin_ns_;
  int64_t start_ns_ = 0;
  int64_t next_ = 1;
};

// Monotonic nanoseconds.
int64_t MonotonicNs();

// Asks for SCHED_FIFO at `priority` for the calling thread and locks the
// process's memory; returns what was obtained, e.g. "SCHED_FIFO priority
// 80, memory locked" or "SCHED_OTHER (SCHED_FIFO not allowed: Operation
// not permitted; run with CAP_SYS_NICE or an rtprio limit)".
std::string TryRealtime(int priority);

// Pins the calling thread to CPU `cpu` (a loop alone on a core wakes on
// time more often: docs/haptic.md "Benchmark"); returns what was obtained,
// e.g. "pinned to CPU 1" or "not pinned (CPU 7 out of range: 2 CPUs)".
std::string TryPin(int cpu);

// Moves the calling thread off CPU `cpu`, onto the others it may use, so
// that the threads (and processes) it starts later leave the loop's core
// alone. Returns what was done, e.g. "other threads on CPUs 0" or "other
// threads not moved (no other CPU)".
std::string KeepOffCpu(int cpu);

}  // namespace dynsolid::haptic
