// The bridge's force rendering (docs/haptic.md "Rendering"): pure logic on
// a clock it is given, so tests drive it with simulated time.
//
// Each tick the device force is computed from the newest contact model the
// server sent (a surface point x_s with normal n, the solid's effective
// stiffness k there, the load F_s the solid carried at that point and the
// point's velocity v_s) by a virtual coupling: a spring K_c (and damper B)
// between the device and a proxy held on the model's surface. The proxy
// yields as the local model says the solid would: under a normal force f
// it sits (f - F_s) / k below x_s. Solving the two springs in series,
//
//   depth  = (x_s + v_s a - x_d) . n        (a: the model's age, capped)
//   f      = k_ser (depth + F_s / k) - B (v_d - v_s) . n,   f >= 0
//   k_ser  = K_c k / (K_c + k)
//
// and F = f n (no pulling: f < 0 is no contact). In quasi-static contact
// the solid carries F_s = f, the proxy is at the surface point and the
// device sits f / K_c beyond it, so the force the user feels is the force
// the solid's own response makes.
//
// Limits, in this order:
//  - K_c = min(max_stiffness, passivity_margin * 2 (b - B) / T):
//    Colgate and Schenkel's bound for a sampled virtual spring K and
//    damper B on a device with physical damping b, period T: the coupling
//    is passive when b > K T / 2 + |B|;
//  - a new model is blended in: at its arrival the difference between the
//    forces the old model (with what is left of its own blend) and the new
//    one give at the device's current state is kept as an offset that
//    decays linearly to zero over blend_time (so the device's own motion
//    still changes the force at once; only the model's jump is spread);
//  - |F| <= max_force;
//  - |F - F_previous| <= max_force_step per tick (a slew limit: no force
//    step exceeds the bound, whatever happens before it);
//  - safety: when no model arrived for model_timeout, or the link to the
//    server is down, the force ramps linearly to zero over ramp_time and
//    (the first tick that sees the silence lowers it, the ramp_time / T-th
//    reaches zero) and stays zero until a model arrives on a working link
//    again (then it is
//    blended in from zero). Params::Validate checks that max_force_step
//    lets the ramp finish in time.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/status.h"

namespace dynsolid::haptic {

// A contact model in the bridge's terms (service.proto ContactModel).
struct LocalModel {
  int64_t step = -1;
  uint64_t pose_seq = 0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d material_point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d applied_force = Eigen::Vector3d::Zero();  // on the solid
  double stiffness = 0;                                     // N/m over the horizon; <= 0: unknown
  double damping = 0;                                       // N s/m
  double static_stiffness = 0;                              // N/m; 0: unknown
};

struct CouplingParams {
  double period = 1e-3;           // T, seconds
  double device_damping = 20.0;   // b, N s/m (the device's physical damping)
  double passivity_margin = 0.8;  // K_c <= margin * 2 (b - B) / T
  double max_stiffness = 1e9;     // N/m, a user cap on K_c
  double virtual_damping = 2.0;   // B, N s/m, at most b / 2
  double max_force = 40.0;        // N, the device's largest force
  // N per tick. Above the fastest change normal contact makes (K_c times
  // the device's travel per tick): a bound below it turns into lag and a
  // limit cycle (measured: 5 N with a 0.5 kg hand pushing 25 N at 28.8
  // kN/m chattered at 20 Hz; 10 N does not).
  double max_force_step = 10.0;
  double blend_time = 0.003;      // s
  double model_timeout = 0.010;   // s without a model: safety ramp
  double ramp_time = 0.010;       // s: the ramp to zero
  double max_prediction = 0.020;  // s: the model's age used in x_s + v_s a, at most
  // InvalidArgument naming the parameter (non-positive values, B > b / 2,
  // a step bound that cannot finish the ramp in ramp_time).
  absl::Status Validate() const;
  // The passivity bound 2 (b - B) / T times the margin, N/m.
  double PassiveStiffness() const;
};

struct DeviceSample {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
};

// One tick's result.
struct RenderedForce {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // on the device, N
  double step = 0;                                  // |F - F_previous|, N
  double coupling_stiffness = 0;                    // K_c used, N/m (0: no model)
  double depth = 0;         // of the device below the model's surface point, m
  bool in_contact = false;  // the model pushes (f > 0)
  bool ramping = false;     // the safety ramp is active (or finished: force held at zero)
  int64_t model_step = -1;  // the step of the model used (-1: none)
};

class Coupling {
 public:
  explicit Coupling(CouplingParams params) : p_(params) {}

  const CouplingParams& params() const { return p_; }

  // A new model arrived at time `now` (seconds on the loop's clock).
  void OnModel(const LocalModel& model, double now, const DeviceSample& device);
  // The link to the server went down (or came back up).
  void SetLinkUp(bool up, double now);
  // The force for this tick.
  RenderedForce Compute(double now, const DeviceSample& device);

  // The model's own force (no blend, limits or safety), for tests: f n.
  Eigen::Vector3d ModelForce(const LocalModel& m, double age, const DeviceSample& d,
                             double* depth = nullptr, double* k_c = nullptr) const;

  bool has_model() const { return model_.has_value(); }
  const std::optional<LocalModel>& model() const { return model_; }
  double last_model_time() const { return model_time_; }
  bool safe_state() const { return safe_; }

 private:
  bool Silent(double now) const;

  const CouplingParams p_;
  std::optional<LocalModel> model_;
  double model_time_ = -1e300;
  // Blend: offset at blend_start decaying to zero over blend_time.
  Eigen::Vector3d offset_ = Eigen::Vector3d::Zero();
  double blend_start_ = -1e300;
  Eigen::Vector3d last_ = Eigen::Vector3d::Zero();  // the force of the last tick
  bool link_up_ = true;
  // Safety ramp.
  bool safe_ = false;  // ramping or held at zero
  Eigen::Vector3d ramp_from_ = Eigen::Vector3d::Zero();
  double ramp_start_ = 0;
};

}  // namespace dynsolid::haptic
