#include "solver/common/worker_pool.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define DYNSOLID_PAUSE() _mm_pause()
#else
#define DYNSOLID_PAUSE() ((void)0)
#endif

namespace dynsolid {
namespace {

// Spin this many rounds (a pause each, some 10-30 microseconds in all)
// before sleeping on the condition variable: a step issues several Runs a
// millisecond apart or less, and a futex wake-up costs more than the work
// of a small Run.
constexpr int kSpinRounds = 1000;

}  // namespace

WorkerPool::WorkerPool(int threads) {
  for (int k = 1; k < threads; ++k) workers_.emplace_back([this, k] { Loop(k); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_.store(true, std::memory_order_release);
  }
  start_cv_.notify_all();
  for (auto& t : workers_) t.join();
}

void WorkerPool::RunRaw(void (*fn)(void*, int), void* ctx) {
  if (workers_.empty()) {
    fn(ctx, 0);
    return;
  }
  fn_ = fn;
  ctx_ = ctx;
  pending_.store(static_cast<int>(workers_.size()), std::memory_order_relaxed);
  {
    // Under the lock, so a worker about to sleep sees the new generation.
    std::lock_guard<std::mutex> lock(mu_);
    generation_.fetch_add(1, std::memory_order_release);
  }
  start_cv_.notify_all();
  fn(ctx, 0);
  for (int i = 0; i < kSpinRounds; ++i) {
    if (pending_.load(std::memory_order_acquire) == 0) return;
    DYNSOLID_PAUSE();
  }
  std::unique_lock<std::mutex> lock(mu_);
  done_cv_.wait(lock, [this] { return pending_.load(std::memory_order_acquire) == 0; });
}

void WorkerPool::Loop(int index) {
  uint64_t seen = 0;
  while (true) {
    bool ready = false;
    for (int i = 0; i < kSpinRounds && !ready; ++i) {
      ready = generation_.load(std::memory_order_acquire) != seen ||
              stop_.load(std::memory_order_acquire);
      if (!ready) DYNSOLID_PAUSE();
    }
    if (!ready) {
      std::unique_lock<std::mutex> lock(mu_);
      start_cv_.wait(lock, [&] {
        return stop_.load(std::memory_order_acquire) ||
               generation_.load(std::memory_order_acquire) != seen;
      });
    }
    if (stop_.load(std::memory_order_acquire)) return;
    seen = generation_.load(std::memory_order_acquire);
    fn_(ctx_, index);
    if (pending_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      std::lock_guard<std::mutex> lock(mu_);
      done_cv_.notify_one();
    }
  }
}

}  // namespace dynsolid
