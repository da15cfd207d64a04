#include "server/work_queue.h"

#include <algorithm>
#include <utility>

#include "server/thread_priority.h"

namespace dynsolid::server {

WorkQueue::WorkQueue(int threads, const char* name, int nice, bool idle) {
  for (int i = 0; i < std::max(threads, 1); ++i) {
    workers_.emplace_back([this, name, nice, idle] { Work(name, nice, idle); });
  }
}

WorkQueue::~WorkQueue() { Join(); }

void WorkQueue::Post(Task task) {
  {
    absl::MutexLock lock(&mu_);
    if (!stopped_) {
      queue_.push_back(std::move(task));
      return;
    }
  }
  task(false);
}

void WorkQueue::Stop() {
  std::deque<Task> cancelled;
  {
    absl::MutexLock lock(&mu_);
    stopped_ = true;
    cancelled.swap(queue_);
  }
  for (Task& task : cancelled) task(false);
}

void WorkQueue::Join() {
  Stop();
  for (std::thread& t : workers_) {
    if (t.joinable()) t.join();
  }
}

bool WorkQueue::HasWorkOrStopped() const { return stopped_ || !queue_.empty(); }

void WorkQueue::Work(const char* name, int nice, bool idle) {
  NameThisThread(name);
  // Best effort: a refusal leaves the worker at its creator's priority.
  (void)LowerThisThreadPriority(nice);
  if (idle) (void)MakeThisThreadIdle();
  for (;;) {
    Task task;
    {
      absl::MutexLock lock(&mu_);
      mu_.Await(absl::Condition(this, &WorkQueue::HasWorkOrStopped));
      if (queue_.empty()) return;  // stopped and drained
      task = std::move(queue_.front());
      queue_.pop_front();
    }
    task(true);
  }
}

}  // namespace dynsolid::server
