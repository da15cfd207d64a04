// A fixed set of worker threads for per-step work (the hot path): Run()
// hands chunk k of a job to thread k (chunk 0 runs on the caller) and
// returns when all are done. Chunk boundaries are fixed by the caller, so
// results joined in chunk order are deterministic. No allocation per Run.
#pragma once

#include <atomic>
#include <condition_variable>
#include <type_traits>
#include <mutex>
#include <thread>
#include <vector>

namespace dynsolid {

class WorkerPool {
 public:
  // `threads` >= 1 chunks per Run (threads - 1 workers).
  explicit WorkerPool(int threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls job(k) for k in [0, size()), concurrently; returns when all end.
  // `job` is called through a plain pointer: no allocation.
  template <typename Job>
  void Run(Job&& job) {
    RunRaw([](void* ctx, int k) { (*static_cast<std::remove_reference_t<Job>*>(ctx))(k); },
           static_cast<void*>(&job));
  }

  // Calls job(part) once for every part in [0, parts), concurrently: each
  // thread takes the next part not yet taken until none is left, so a
  // slow part does not hold back the parts behind it. Which thread runs a
  // part varies from run to run: a part must write only its own outputs
  // (its rows, its buffer), so the results depend on the parts alone.
  template <typename Job>
  void RunParts(int parts, Job&& job) {
    std::atomic<int> next{0};
    Run([&](int) {
      for (int k = next.fetch_add(1, std::memory_order_relaxed); k < parts;
           k = next.fetch_add(1, std::memory_order_relaxed)) {
        job(k);
      }
    });
  }

 private:
  void RunRaw(void (*fn)(void*, int), void* ctx);
  void Loop(int index);

  std::vector<std::thread> workers_;
  std::mutex mu_;
  std::condition_variable start_cv_, done_cv_;
  // fn_ and ctx_ are written before generation_ is released and read after
  // it is acquired. Workers spin for a while (worker_pool.cc), then sleep on
  // start_cv_.
  void (*fn_)(void*, int) = nullptr;
  void* ctx_ = nullptr;
  std::atomic<uint64_t> generation_{0};
  std::atomic<int> pending_{0};
  std::atomic<bool> stop_{false};
};

}  // namespace dynsolid
