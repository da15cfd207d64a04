#include "clients/haptic/metrics.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace dynsolid::haptic {

LoopMetrics::LoopMetrics(double period, size_t reserve_ticks) : period_(period) {
  period_us_.reserve(reserve_ticks);
  lateness_us_.reserve(reserve_ticks);
  compute_us_.reserve(reserve_ticks);
  model_age_ms_.reserve(reserve_ticks);
}

void LoopMetrics::Tick(double woke, double deadline, double compute, double force_step,
                       double model_age) {
  ++ticks_;
  if (last_woke_ >= 0) period_us_.push_back((woke - last_woke_) * 1e6);
  last_woke_ = woke;
  lateness_us_.push_back((woke - deadline) * 1e6);
  compute_us_.push_back(compute * 1e6);
  if (model_age >= 0) model_age_ms_.push_back(model_age * 1e3);
  largest_step_ = std::max(largest_step_, force_step);
}

void LoopMetrics::ModelReceived(double t) {
  ++models_;
  if (first_model_ < 0) first_model_ = t;
  last_model_ = t;
}

void LoopMetrics::RampStarted(double t) {
  ++ramps_;
  ramp_start_ = t;
}

void LoopMetrics::ForceZeroAfterRamp(double t) {
  if (ramp_start_ < 0) return;
  longest_ramp_ = std::max(longest_ramp_, t - ramp_start_);
  ramp_start_ = -1;
}

void LoopMetrics::MaxForce(double f) { max_force_ = std::max(max_force_, f); }

LoopSummary LoopMetrics::Summarize(double seconds) const {
  LoopSummary s;
  s.seconds = seconds;
  s.ticks = ticks_;
  s.period_target_us = period_ * 1e6;
  s.period_p50_us = Percentile(period_us_, 0.5);
  s.period_p99_us = Percentile(period_us_, 0.99);
  s.period_p999_us = Percentile(period_us_, 0.999);
  s.period_max_us =
      period_us_.empty() ? 0 : *std::max_element(period_us_.begin(), period_us_.end());
  std::vector<double> err(period_us_.size());
  for (size_t i = 0; i < err.size(); ++i) err[i] = std::abs(period_us_[i] - period_ * 1e6);
  s.period_error_p50_us = Percentile(err, 0.5);
  s.period_error_p99_us = Percentile(err, 0.99);
  s.period_error_p999_us = Percentile(err, 0.999);
  s.period_error_max_us = err.empty() ? 0 : *std::max_element(err.begin(), err.end());
  s.lateness_p99_us = Percentile(lateness_us_, 0.99);
  s.lateness_max_us =
      lateness_us_.empty() ? 0 : *std::max_element(lateness_us_.begin(), lateness_us_.end());
  s.miss_threshold_us = 0.25 * period_ * 1e6;
  int64_t misses = 0;
  for (double l : lateness_us_) misses += l > s.miss_threshold_us ? 1 : 0;
  s.deadline_misses = misses + skipped_;
  s.skipped_ticks = skipped_;
  s.model_age_p50_ms = Percentile(model_age_ms_, 0.5);
  s.model_age_p99_ms = Percentile(model_age_ms_, 0.99);
  s.model_age_max_ms =
      model_age_ms_.empty() ? 0 : *std::max_element(model_age_ms_.begin(), model_age_ms_.end());
  s.models_received = models_;
  if (models_ > 1 && last_model_ > first_model_) {
    s.model_refresh_hz = (models_ - 1) / (last_model_ - first_model_);
  }
  s.largest_force_step_n = largest_step_;
  s.max_force_n = max_force_;
  s.compute_p50_us = Percentile(compute_us_, 0.5);
  s.compute_p99_us = Percentile(compute_us_, 0.99);
  s.compute_p999_us = Percentile(compute_us_, 0.999);
  s.compute_max_us =
      compute_us_.empty() ? 0 : *std::max_element(compute_us_.begin(), compute_us_.end());
  s.safety_ramps = ramps_;
  s.ramps_interrupted = ramps_interrupted_;
  s.longest_ramp_ms = longest_ramp_ * 1e3;
  return s;
}

std::string LoopSummary::Text() const {
  std::string out;
  absl::StrAppendFormat(&out, "haptic loop: %d ticks in %.2f s (target period %.0f us), %s\n",
                        ticks, seconds, period_target_us, realtime);
  absl::StrAppendFormat(&out,
                        "  period us: p50 %.1f  p99 %.1f  p99.9 %.1f  max %.1f; error from T: "
                        "p50 %.1f  p99 %.1f  p99.9 %.1f  max %.1f\n",
                        period_p50_us, period_p99_us, period_p999_us, period_max_us,
                        period_error_p50_us, period_error_p99_us, period_error_p999_us,
                        period_error_max_us);
  absl::StrAppendFormat(&out,
                        "  deadline misses: %d (woke > %.0f us late, or skipped: %d); lateness "
                        "p99 %.1f us, max %.1f us\n",
                        deadline_misses, miss_threshold_us, skipped_ticks, lateness_p99_us,
                        lateness_max_us);
  absl::StrAppendFormat(&out,
                        "  contact models: %d received, refresh %.1f Hz; age ms p50 %.2f  p99 "
                        "%.2f  max %.2f; pose -> model round trip ms p50 %.2f  p99 %.2f\n",
                        models_received, model_refresh_hz, model_age_p50_ms, model_age_p99_ms,
                        model_age_max_ms, round_trip_p50_ms, round_trip_p99_ms);
  absl::StrAppendFormat(&out,
                        "  force: largest step %.3f N (bound %.3f N), largest %.2f N; compute "
                        "us p50 %.2f  p99 %.2f  p99.9 %.2f  max %.2f\n",
                        largest_force_step_n, force_step_bound_n, max_force_n, compute_p50_us,
                        compute_p99_us, compute_p999_us, compute_max_us);
  absl::StrAppendFormat(
      &out,
      "  safety ramps: %d (%d cut short by a model; longest to zero %.1f ms); "
      "link: %d replies, %d poses sent, %d refused, %d reconnects%s\n",
      safety_ramps, ramps_interrupted, longest_ramp_ms, replies, poses_sent, poses_rejected,
      reconnects, last_rejection.empty() ? "" : absl::StrCat(" (last: ", last_rejection, ")"));
  return out;
}

namespace {

std::string JsonString(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      absl::StrAppendFormat(&out, "\\u%04x", c);
    } else {
      out += c;
    }
  }
  return out + "\"";
}

}  // namespace

std::string LoopSummary::Json() const {
  std::string o = "{\n";
  auto num = [&](const char* k, double v, bool last = false) {
    absl::StrAppendFormat(&o, "  \"%s\": %.6g%s\n", k, std::isfinite(v) ? v : 0.0, last ? "" : ",");
  };
  num("seconds", seconds);
  num("ticks", static_cast<double>(ticks));
  num("period_target_us", period_target_us);
  num("period_p50_us", period_p50_us);
  num("period_p99_us", period_p99_us);
  num("period_p999_us", period_p999_us);
  num("period_max_us", period_max_us);
  num("period_error_p50_us", period_error_p50_us);
  num("period_error_p99_us", period_error_p99_us);
  num("period_error_p999_us", period_error_p999_us);
  num("period_error_max_us", period_error_max_us);
  num("lateness_p99_us", lateness_p99_us);
  num("lateness_max_us", lateness_max_us);
  num("deadline_misses", static_cast<double>(deadline_misses));
  num("skipped_ticks", static_cast<double>(skipped_ticks));
  num("miss_threshold_us", miss_threshold_us);
  num("model_age_p50_ms", model_age_p50_ms);
  num("model_age_p99_ms", model_age_p99_ms);
  num("model_age_max_ms", model_age_max_ms);
  num("models_received", static_cast<double>(models_received));
  num("model_refresh_hz", model_refresh_hz);
  num("round_trip_p50_ms", round_trip_p50_ms);
  num("round_trip_p99_ms", round_trip_p99_ms);
  num("largest_force_step_n", largest_force_step_n);
  num("force_step_bound_n", force_step_bound_n);
  num("max_force_n", max_force_n);
  num("compute_p50_us", compute_p50_us);
  num("compute_p99_us", compute_p99_us);
  num("compute_p999_us", compute_p999_us);
  num("compute_max_us", compute_max_us);
  num("safety_ramps", static_cast<double>(safety_ramps));
  num("ramps_interrupted", static_cast<double>(ramps_interrupted));
  num("longest_ramp_ms", longest_ramp_ms);
  num("replies", static_cast<double>(replies));
  num("poses_sent", static_cast<double>(poses_sent));
  num("poses_rejected", static_cast<double>(poses_rejected));
  num("reconnects", static_cast<double>(reconnects));
  absl::StrAppend(&o, "  \"last_rejection\": ", JsonString(last_rejection), ",\n");
  absl::StrAppend(&o, "  \"realtime\": ", JsonString(realtime), "\n}\n");
  return o;
}

}  // namespace dynsolid::haptic
