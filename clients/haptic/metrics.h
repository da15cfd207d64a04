// The bridge's loop metrics (docs/haptic.md "Metrics"): per-tick samples
// kept in pre-reserved arrays (the loop does not allocate while they
// last), summarized at exit as text and JSON.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "clients/lib/stats.h"

namespace dynsolid::haptic {

// The client library's nearest-rank percentile.
using client::Percentile;

struct LoopSummary {
  double seconds = 0;
  int64_t ticks = 0;
  double period_target_us = 0;
  // Loop period (time between consecutive ticks' wake-ups) and its error
  // |period - T|, microseconds.
  double period_p50_us = 0, period_p99_us = 0, period_p999_us = 0, period_max_us = 0;
  double period_error_p50_us = 0, period_error_p99_us = 0, period_error_p999_us = 0,
         period_error_max_us = 0;
  // Wake-up after the deadline, microseconds.
  double lateness_p99_us = 0, lateness_max_us = 0;
  // Ticks that woke more than miss_threshold after their deadline, plus
  // deadlines skipped outright.
  int64_t deadline_misses = 0;
  int64_t skipped_ticks = 0;
  double miss_threshold_us = 0;
  // Age of the contact model in use at each tick with a model, ms.
  double model_age_p50_ms = 0, model_age_p99_ms = 0, model_age_max_ms = 0;
  int64_t models_received = 0;
  double model_refresh_hz = 0;  // models received per second while models came
  // From writing a pose to receiving the first model made for it, ms.
  double round_trip_p50_ms = 0, round_trip_p99_ms = 0;
  // |F_k - F_(k-1)|, newtons, and the bound.
  double largest_force_step_n = 0, force_step_bound_n = 0;
  double max_force_n = 0;
  // Time in the force computation (model intake, coupling, limits) per
  // tick, microseconds.
  double compute_p50_us = 0, compute_p99_us = 0, compute_p999_us = 0, compute_max_us = 0;
  int64_t safety_ramps = 0;       // times the safety ramp started from a non-zero force
  int64_t ramps_interrupted = 0;  // of those, cut short by a model before zero
  double longest_ramp_ms = 0;     // from a ramp's start to zero force
  std::string realtime;           // what TryRealtime obtained
  // Link.
  int64_t replies = 0, poses_sent = 0, poses_rejected = 0, reconnects = 0;
  std::string last_rejection;

  std::string Text() const;
  std::string Json() const;
};

class LoopMetrics {
 public:
  explicit LoopMetrics(double period, size_t reserve_ticks);
  // One tick: its wake-up time and deadline (s), the force computation's
  // time (s), the force step (N), the model's age (s, < 0: no model).
  void Tick(double woke, double deadline, double compute, double force_step, double model_age);
  void Skipped(int64_t n) { skipped_ += n; }
  void ModelReceived(double t);
  void RampStarted(double t);
  void ForceZeroAfterRamp(double t);
  void RampInterrupted() {
    ramp_start_ = -1;
    ++ramps_interrupted_;
  }
  void MaxForce(double f);
  LoopSummary Summarize(double seconds) const;

 private:
  const double period_;
  std::vector<double> period_us_, lateness_us_, compute_us_, model_age_ms_;
  double last_woke_ = -1;
  double largest_step_ = 0, max_force_ = 0;
  int64_t skipped_ = 0, ticks_ = 0;
  int64_t models_ = 0;
  double first_model_ = -1, last_model_ = -1;
  int64_t ramps_ = 0, ramps_interrupted_ = 0;
  double ramp_start_ = -1, longest_ramp_ = 0;
};

}  // namespace dynsolid::haptic
