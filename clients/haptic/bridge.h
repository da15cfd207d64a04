// The bridge's 1 kHz loop (docs/haptic.md): each tick reads the device,
// takes the newest contact model from the link, computes the force
// (Coupling), writes it to the device, and posts the pose with that force
// to the link. The network is never inside the loop (ProbeLink's threads
// do the gRPC calls).
#pragma once

#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "clients/haptic/coupling.h"
#include "clients/haptic/device.h"
#include "clients/haptic/metrics.h"
#include "clients/haptic/probe_link.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::haptic {

// The contact model in the bridge's terms.
LocalModel ToLocalModel(const ContactModel& m);

struct BridgeOptions {
  CouplingParams coupling;
  // Run this long (seconds); 0: until the device's script ends.
  double seconds = 0;
  // Ask for SCHED_FIFO at this priority (0: do not ask).
  int rt_priority = 80;
  // Pin the loop's thread to this CPU (-1: do not pin).
  int cpu = -1;
  // Keep a per-tick trace (for force-depth curves; TraceCsv).
  bool trace = false;
  // The first pose's sequence number (a link that already sent poses).
  uint64_t first_seq = 1;
  // The clock sleeps to this long before each deadline and spins the rest,
  // seconds.
  double spin_margin = 100e-6;
};

// One tick of the trace.
struct TraceRow {
  double t = 0;
  Eigen::Vector3d device = Eigen::Vector3d::Zero();
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  // The model in use: its step, point, material point, normal, stiffness.
  int64_t model_step = -1;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d material_point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double stiffness = 0, static_stiffness = 0, coupling_stiffness = 0;
  double model_age = -1;
  bool in_contact = false, ramping = false, link_up = false;
};

class Bridge {
 public:
  // `link` may be null (no server: the force stays zero; tests).
  Bridge(Device& device, ProbeLink* link, BridgeOptions options);

  // Runs the loop until the time is up, the device's script ends or *stop.
  LoopSummary Run(const std::atomic<bool>& stop);

  const std::vector<TraceRow>& trace() const { return trace_; }
  // t, device xyz, force xyz, force along the normal, depth of the device
  // below the material point along the normal (from the rest surface), the
  // surface's dent there, model step, k, static k, K_c, age, flags.
  std::string TraceCsv() const;

 private:
  Device& device_;
  ProbeLink* link_;
  const BridgeOptions options_;
  std::vector<TraceRow> trace_;
};

}  // namespace dynsolid::haptic
