#include "clients/haptic/coupling.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace dynsolid::haptic {

absl::Status CouplingParams::Validate() const {
  auto positive = [](double v, const char* name) -> absl::Status {
    if (!(v > 0) || !std::isfinite(v)) {
      return absl::InvalidArgumentError(absl::StrCat(name, " must be > 0, got ", v));
    }
    return absl::OkStatus();
  };
  for (const auto& [v, name] : {std::pair{period, "period"},
                                {device_damping, "device_damping"},
                                {passivity_margin, "passivity_margin"},
                                {max_stiffness, "max_stiffness"},
                                {max_force, "max_force"},
                                {max_force_step, "max_force_step"},
                                {blend_time, "blend_time"},
                                {model_timeout, "model_timeout"},
                                {ramp_time, "ramp_time"}}) {
    if (absl::Status s = positive(v, name); !s.ok()) return s;
  }
  if (passivity_margin > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("passivity_margin must be in (0, 1], got ", passivity_margin));
  }
  if (!(virtual_damping >= 0) || virtual_damping > 0.5 * device_damping) {
    return absl::InvalidArgumentError(
        absl::StrCat("virtual_damping must be in [0, device_damping / 2 = ", 0.5 * device_damping,
                     "], got ", virtual_damping));
  }
  if (!(max_prediction >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_prediction must be >= 0, got ", max_prediction));
  }
  // The ramp takes ceil(ramp_time / period) ticks from at most max_force.
  const double ticks = std::max(1.0, std::floor(ramp_time / period + 1e-9));
  if (max_force_step * ticks < max_force * (1 - 1e-12)) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_force_step (", max_force_step, " N per tick) cannot take max_force (",
                     max_force, " N) to zero within ramp_time (", ramp_time, " s = ", ticks,
                     " ticks): it must be >= ", max_force / ticks));
  }
  return absl::OkStatus();
}

double CouplingParams::PassiveStiffness() const {
  return passivity_margin * 2.0 * (device_damping - virtual_damping) / period;
}

Eigen::Vector3d Coupling::ModelForce(const LocalModel& m, double age, const DeviceSample& d,
                                     double* depth_out, double* k_c_out) const {
  const double a = std::clamp(age, 0.0, p_.max_prediction);
  const Eigen::Vector3d n = m.normal;
  const Eigen::Vector3d xs = m.point + a * m.velocity;
  const double depth = (xs - d.position).dot(n);
  const double carried = std::max(0.0, -m.applied_force.dot(n));  // F_s, pushing in
  const double kc = std::min(p_.max_stiffness, p_.PassiveStiffness());
  double pre;
  if (m.stiffness > 0) {
    const double k_ser = kc * m.stiffness / (kc + m.stiffness);
    pre = k_ser * (depth + carried / m.stiffness);
  } else {
    pre = kc * depth;
  }
  if (depth_out != nullptr) *depth_out = depth;
  if (k_c_out != nullptr) *k_c_out = kc;
  if (!(pre > 0)) return Eigen::Vector3d::Zero();
  const double f = pre - p_.virtual_damping * (d.velocity - m.velocity).dot(n);
  return std::max(0.0, f) * n;
}

bool Coupling::Silent(double now) const {
  return !link_up_ || !model_.has_value() || now - model_time_ > p_.model_timeout;
}

void Coupling::OnModel(const LocalModel& model, double now, const DeviceSample& device) {
  // Blend: the offset between what the old model (with what is left of its
  // own blend) and the new one give at this device state decays to zero
  // over blend_time. Coming out of the safety ramp (or with no model yet)
  // the blend starts from the force last rendered (zero after the ramp).
  Eigen::Vector3d before;
  if (model_.has_value() && !safe_) {
    const double w = std::max(0.0, 1.0 - (now - blend_start_) / p_.blend_time);
    before = ModelForce(*model_, now - model_time_, device) + w * offset_;
  } else {
    before = last_;
  }
  model_ = model;
  model_time_ = now;
  offset_ = before - ModelForce(model, 0.0, device);
  blend_start_ = now;
}

void Coupling::SetLinkUp(bool up, double now) {
  (void)now;
  link_up_ = up;
}

RenderedForce Coupling::Compute(double now, const DeviceSample& device) {
  RenderedForce out;
  const bool silent = Silent(now);
  if (silent && !safe_) {
    safe_ = true;
    ramp_from_ = last_;
    ramp_start_ = now;
  } else if (!silent && safe_) {
    safe_ = false;  // OnModel set the blend from the ramp's force
  }
  Eigen::Vector3d f;
  if (safe_) {
    // The first tick that sees the silence already lowers the force; the
    // last of ramp_time / T ticks reaches zero.
    double s = 1.0 - (now - ramp_start_ + p_.period) / p_.ramp_time;
    if (s < 1e-9) s = 0;
    f = s * ramp_from_;
    out.ramping = true;
  } else {
    const LocalModel& m = *model_;
    f = ModelForce(m, now - model_time_, device, &out.depth, &out.coupling_stiffness);
    out.in_contact = f.squaredNorm() > 0;
    const double w = std::max(0.0, 1.0 - (now - blend_start_) / p_.blend_time);
    f += w * offset_;
    if (f.dot(m.normal) < 0) f.setZero();  // a blend never pulls
    out.model_step = m.step;
  }
  // The device's limit, then the step bound.
  const double norm = f.norm();
  if (norm > p_.max_force) f *= p_.max_force / norm;
  const Eigen::Vector3d step = f - last_;
  const double s = step.norm();
  if (s > p_.max_force_step) f = last_ + step * (p_.max_force_step / s);
  out.step = (f - last_).norm();
  out.force = f;
  last_ = f;
  return out;
}

}  // namespace dynsolid::haptic
