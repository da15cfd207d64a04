#include "solver/common/worker_pool.h"

#include <chrono>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define DYNSOLID_PAUSE() _mm_pause()
#else
#define DYNSOLID_PAUSE() ((void)0)
#endif

namespace dynsolid {
namespace {

// Spin this long before sleeping on the condition variable. A step issues
// a dozen Runs with serial work between them (the mass solve, traces,
// the integrator's vector updates: tens of microseconds); a worker that
// fell asleep in such a gap costs a futex wake-up (several microseconds)
// on the next Run, more than the work of a small Run. 1000 pauses (10-30
// microseconds, depending on the CPU's pause) was shorter than those gaps:
// block3's node products ran at half speed. A time limit, not a count,
// because a pause lasts 10 to 140 cycles from one CPU to the next.
constexpr auto kSpin = std::chrono::microseconds(250);
// The first part of it busy (pauses); the rest yields the core between
// checks, so that where threads outnumber cores (tests run side by side,
// many sessions on one server) a waiting worker gives its core to whoever
// has work instead of burning it.
constexpr auto kBusySpin = std::chrono::microseconds(20);

// Waits (pausing, then yielding) until ready() or kSpin has passed;
// returns ready().
template <typename Ready>
bool SpinUntil(Ready ready) {
  const auto start = std::chrono::steady_clock::now();
  while (true) {
    for (int i = 0; i < 32; ++i) {
      if (ready()) return true;
      DYNSOLID_PAUSE();
    }
    const auto waited = std::chrono::steady_clock::now() - start;
    if (waited >= kSpin) return ready();
    if (waited >= kBusySpin) std::this_thread::yield();
  }
}

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
  if (SpinUntil([this] { return pending_.load(std::memory_order_acquire) == 0; })) return;
  std::unique_lock<std::mutex> lock(mu_);
  done_cv_.wait(lock, [this] { return pending_.load(std::memory_order_acquire) == 0; });
}

void WorkerPool::Loop(int index) {
  uint64_t seen = 0;
  while (true) {
    const bool ready = SpinUntil([&] {
      return generation_.load(std::memory_order_acquire) != seen ||
             stop_.load(std::memory_order_acquire);
    });
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
