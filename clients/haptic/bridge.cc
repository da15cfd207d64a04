#include "clients/haptic/bridge.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "absl/strings/str_format.h"
#include "clients/haptic/loop_clock.h"

namespace dynsolid::haptic {
namespace {

Eigen::Vector3d V(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// Touches 256 KB of this thread's stack, so mlockall(MCL_CURRENT) finds it
// mapped and the loop never faults a new stack page in.
__attribute__((noinline)) void PrefaultStack() {
  volatile char buffer[256 * 1024];
  for (size_t i = 0; i < sizeof(buffer); i += 4096) buffer[i] = 0;
}

}  // namespace

LocalModel ToLocalModel(const ContactModel& m) {
  LocalModel l;
  l.step = m.step();
  l.pose_seq = m.pose_seq();
  l.point = V(m.point());
  l.material_point = V(m.material_point());
  l.normal = V(m.normal());
  if (l.normal.squaredNorm() > 0) l.normal.normalize();
  l.velocity = V(m.velocity());
  l.applied_force = V(m.applied_force());
  l.stiffness = m.stiffness();
  l.damping = m.damping();
  l.static_stiffness = m.static_stiffness();
  return l;
}

Bridge::Bridge(Device& device, ProbeLink* link, BridgeOptions options)
    : device_(device), link_(link), options_(options) {}

LoopSummary Bridge::Run(const std::atomic<bool>& stop) {
  const CouplingParams& cp = options_.coupling;
  Coupling coupling(cp);
  const double expected = options_.seconds > 0     ? options_.seconds
                          : device_.duration() > 0 ? device_.duration() + 1.0
                                                   : 600.0;
  const size_t reserve = static_cast<size_t>(expected / cp.period * 1.1) + 16;
  LoopMetrics metrics(cp.period, reserve);
  if (options_.trace) trace_.reserve(reserve);
  // After the reservations: mlockall(MCL_CURRENT) faults them in, so the
  // loop takes no page fault writing its samples (a fault can wait for the
  // mmap lock behind another thread's mapping: measured, 5-10 ms gaps).
  PrefaultStack();
  std::string realtime =
      options_.rt_priority > 0 ? TryRealtime(options_.rt_priority) : "SCHED_OTHER (not asked)";
  if (options_.cpu >= 0) realtime += ", " + TryPin(options_.cpu);

  DeadlineClock clock(cp.period, options_.spin_margin);
  clock.Start();
  uint64_t seq = options_.first_seq - 1;
  double model_time = -1;  // loop time the model in use arrived
  bool was_ramping = false, ramp_open = false;
  ContactModel incoming;
  ProbePose pose;  // reused: no allocation per tick once its fields exist
  std::chrono::steady_clock::time_point arrival;
  for (;;) {
    const DeadlineClock::Tick tick = clock.Wait();
    if (stop.load(std::memory_order_relaxed)) break;
    if (options_.seconds > 0 && tick.woke > options_.seconds) break;
    if (options_.seconds <= 0 && device_.Finished(tick.woke)) break;
    if (link_ != nullptr && link_->failed()) break;  // refused for good
    if (tick.skipped > 0) metrics.Skipped(tick.skipped);
    const DeviceState ds = device_.Read(tick.woke);
    const int64_t c0 = MonotonicNs();
    DeviceSample sample{ds.position, ds.velocity};
    const bool up = link_ != nullptr && link_->up();
    coupling.SetLinkUp(up, tick.woke);
    if (link_ != nullptr && link_->TakeModel(&incoming, &arrival)) {
      const double at =
          (std::chrono::duration_cast<std::chrono::nanoseconds>(arrival.time_since_epoch())
               .count() -
           clock.start_ns()) *
          1e-9;
      coupling.OnModel(ToLocalModel(incoming), tick.woke, sample);
      model_time = std::min(at, tick.woke);
      metrics.ModelReceived(tick.woke);
    }
    const RenderedForce r = coupling.Compute(tick.woke, sample);
    const int64_t c1 = MonotonicNs();
    device_.Write(r.force, tick.woke);
    if (link_ != nullptr) {
      pose.set_seq(++seq);
      pose.mutable_position()->set_x(ds.position.x());
      pose.mutable_position()->set_y(ds.position.y());
      pose.mutable_position()->set_z(ds.position.z());
      pose.mutable_orientation()->set_w(ds.orientation.w());
      pose.mutable_orientation()->set_x(ds.orientation.x());
      pose.mutable_orientation()->set_y(ds.orientation.y());
      pose.mutable_orientation()->set_z(ds.orientation.z());
      pose.set_buttons(ds.buttons);
      pose.set_device_time_us(ds.device_time_us);
      pose.mutable_coupling_force()->set_x(r.force.x());
      pose.mutable_coupling_force()->set_y(r.force.y());
      pose.mutable_coupling_force()->set_z(r.force.z());
      pose.set_model_step(r.model_step);
      link_->PostPose(pose);
    }
    const bool using_model = !r.ramping && coupling.has_model();
    const double age = using_model && model_time >= 0 ? tick.woke - model_time : -1;
    metrics.Tick(tick.woke, tick.deadline, (c1 - c0) * 1e-9, r.step, age);
    metrics.MaxForce(r.force.norm());
    if (r.ramping && !was_ramping && r.force.squaredNorm() > 0) {
      // A ramp from zero (before the first model, or out of contact) is
      // no safety event.
      metrics.RampStarted(tick.woke);
      ramp_open = true;
    }
    if (ramp_open && r.force.squaredNorm() == 0) {
      metrics.ForceZeroAfterRamp(tick.woke);
      ramp_open = false;
    }
    if (ramp_open && !r.ramping) {
      metrics.RampInterrupted();  // a model came back before zero
      ramp_open = false;
    }
    was_ramping = r.ramping;
    if (options_.trace && trace_.size() < trace_.capacity()) {
      TraceRow row;
      row.t = tick.woke;
      row.device = ds.position;
      row.force = r.force;
      row.in_contact = r.in_contact;
      row.ramping = r.ramping;
      row.link_up = up;
      row.coupling_stiffness = r.coupling_stiffness;
      row.model_age = age;
      if (coupling.has_model()) {
        const LocalModel& m = *coupling.model();
        row.model_step = m.step;
        row.point = m.point;
        row.material_point = m.material_point;
        row.normal = m.normal;
        row.stiffness = m.stiffness;
        row.static_stiffness = m.static_stiffness;
      }
      trace_.push_back(row);
    }
  }
  // Leave the device at rest.
  device_.Write(Eigen::Vector3d::Zero(), clock.Now());
  LoopSummary s = metrics.Summarize(clock.Now());
  s.realtime = realtime;
  s.force_step_bound_n = cp.max_force_step;
  if (link_ != nullptr) {
    const ProbeLink::Counters c = link_->counters();
    s.replies = c.replies;
    s.poses_sent = c.poses_sent;
    s.poses_rejected = c.rejected;
    s.reconnects = c.reconnects;
    s.last_rejection = c.last_rejection;
    const std::vector<double> rt = link_->round_trips();
    s.round_trip_p50_ms = 1e3 * Percentile(rt, 0.5);
    s.round_trip_p99_ms = 1e3 * Percentile(rt, 0.99);
  }
  return s;
}

std::string Bridge::TraceCsv() const {
  std::string out =
      "t,x,y,z,fx,fy,fz,f_normal,depth,dent,model_step,k,k_static,k_coupling,model_age,"
      "in_contact,ramping,link_up\n";
  for (const TraceRow& r : trace_) {
    const bool has = r.model_step >= 0;
    const double fn = has ? r.force.dot(r.normal) : 0;
    const double depth = has ? (r.material_point - r.device).dot(r.normal) : 0;
    const double dent = has ? (r.material_point - r.point).dot(r.normal) : 0;
    absl::StrAppendFormat(&out,
                          "%.6f,%.7f,%.7f,%.7f,%.5f,%.5f,%.5f,%.5f,%.7f,%.7f,%d,%.6g,%.6g,"
                          "%.6g,%.6f,%d,%d,%d\n",
                          r.t, r.device.x(), r.device.y(), r.device.z(), r.force.x(), r.force.y(),
                          r.force.z(), fn, depth, dent, r.model_step, r.stiffness,
                          r.static_stiffness, r.coupling_stiffness, r.model_age,
                          r.in_contact ? 1 : 0, r.ramping ? 1 : 0, r.link_up ? 1 : 0);
  }
  return out;
}

}  // namespace dynsolid::haptic
