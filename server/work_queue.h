// A few worker threads for work too slow for gRPC's callback threads
// (building a solid). Tasks run in the order posted.
//
// Every posted task is called exactly once: task(true) on a worker, or
// task(false) when the queue stopped before the task started (so a reactor
// waiting on it can still Finish).
#pragma once

#include <deque>
#include <functional>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"

namespace dynsolid::server {

class WorkQueue {
 public:
  using Task = std::function<void(bool run)>;

  // Workers are named `name` (thread_priority.h NameThisThread); `nice`
  // (0..19) is added to each worker's nice value when it starts; 0 leaves
  // them at their creator's priority.
  // With `idle` they run under SCHED_IDLE instead (MakeThisThreadIdle).
  explicit WorkQueue(int threads, const char* name = "work", int nice = 0, bool idle = false);
  ~WorkQueue();  // Stop(), then Join()
  WorkQueue(const WorkQueue&) = delete;
  WorkQueue& operator=(const WorkQueue&) = delete;

  // Queues `task`, or calls task(false) on this thread after Stop.
  void Post(Task task);

  // Stops accepting: tasks not yet started are called with false (on this
  // thread); running tasks continue. Does not wait for them.
  void Stop();

  // Stop(), then waits for running tasks and joins the workers.
  void Join();

 private:
  void Work(const char* name, int nice, bool idle);
  bool HasWorkOrStopped() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  absl::Mutex mu_;
  std::deque<Task> queue_ ABSL_GUARDED_BY(mu_);
  bool stopped_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<std::thread> workers_;
};

}  // namespace dynsolid::server
