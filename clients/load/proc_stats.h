// Where the CPU went during a load run, from /proc (Linux): per thread of a
// process, grouped by thread name, its time on a CPU and its time waiting
// on a run queue for one (schedstat: ready to run, but every core was
// busy); and the machine's busy cores (/proc/stat). Differences of two
// snapshots say which thread ran out of CPU: a thread that waits long on
// the run queue had work and no core to do it on.
#pragma once

#include <sys/types.h>

#include <map>
#include <string>

namespace dynsolid::load {

struct ThreadTime {
  int threads = 0;
  double cpu_s = 0;   // on a CPU
  double wait_s = 0;  // runnable, waiting for a CPU
  double runs = 0;    // times it was put on a CPU
};

struct CpuSnapshot {
  bool ok = false;
  std::map<std::string, ThreadTime> by_name;  // thread name (comm) -> summed
  double machine_busy_s = 0, machine_total_s = 0;  // all cores, from /proc/stat
};

// The threads of `pid` (0: none) by name, and the machine's CPU time.
// Threads that ended between two snapshots are missing from the later one.
CpuSnapshot TakeCpuSnapshot(pid_t pid);

// Per second of `seconds`: the ms each thread name spent on a CPU and
// waiting for one between `a` and `b`, and the cores the machine kept busy.
struct CpuUse {
  int threads = 0;
  double cpu_ms_per_s = 0, wait_ms_per_s = 0;
  double runs_per_s = 0;  // wait / runs: the mean wait for a CPU each time
  // Sums another's threads and times into this one (a group of names).
  void Add(const CpuUse& u) {
    threads += u.threads;
    cpu_ms_per_s += u.cpu_ms_per_s;
    wait_ms_per_s += u.wait_ms_per_s;
    runs_per_s += u.runs_per_s;
  }
};
std::map<std::string, CpuUse> CpuBetween(const CpuSnapshot& a, const CpuSnapshot& b,
                                         double seconds);
double BusyCoresBetween(const CpuSnapshot& a, const CpuSnapshot& b);

}  // namespace dynsolid::load
