// Lowering the scheduling priority of the calling thread (Linux: the nice
// value is per thread and inherited by threads it creates). Lowering needs
// no privilege; raising it back does, so a thread lowered here stays low.
// The server runs its streaming threads (frame encoding and gRPC's own
// threads) lower than the simulation threads, so that when the cores are
// busy frames are skipped instead of steps.
#pragma once

#include "absl/status/status.h"

namespace dynsolid::server {

// Adds `delta` (0..19) to the calling thread's nice value (capped at 19).
// InvalidArgument for a delta out of range; Internal (with errno's text)
// if the system refuses.
absl::Status LowerThisThreadPriority(int delta);

// Moves the calling thread to the SCHED_IDLE policy: it runs only when no
// normal thread (of its scheduling group) wants the CPU, and a normal thread
// that wakes up preempts it at once (a lowered nice value only weighs the
// share; the kernel may let a niced thread finish its slice first).
// Needs no privilege; inherited by threads it creates. Internal (with
// errno's text) if the system refuses.
absl::Status MakeThisThreadIdle();

// Whether the calling thread runs under SCHED_IDLE.
bool ThisThreadIsIdle();

// The calling thread's nice value.
int ThisThreadNice();

// Names the calling thread (at most 15 characters are kept), as `top -H`
// and /proc/PID/task/TID/comm show it: the server's threads are "sim",
// "journal", "encode" and "build" (the solver's step workers, started while
// building, carry "build" too); gRPC names its own.
void NameThisThread(const char* name);

// The calling thread's time so far, ms: on a CPU, and ready to run but
// waiting for one (Linux /proc/thread-self/schedstat; both 0 where it
// cannot be read).
struct ThreadCpu {
  double cpu_ms = 0, wait_ms = 0;
};
ThreadCpu ThisThreadCpu();

}  // namespace dynsolid::server
