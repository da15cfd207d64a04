#include "clients/haptic/device.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace dynsolid::haptic {

absl::StatusOr<Trajectory> Trajectory::Parse(const std::string& text, const std::string& origin) {
  std::vector<Key> keys;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    const size_t hash = line.find('#');
    if (hash != absl::string_view::npos) line = line.substr(0, hash);
    std::vector<absl::string_view> tok =
        absl::StrSplit(line, absl::ByAnyChar(" \t,"), absl::SkipEmpty());
    if (tok.empty()) continue;
    auto where = [&] { return absl::StrCat(origin, ":", line_no, ": "); };
    if (tok.size() != 4 && tok.size() != 8 && tok.size() != 9) {
      return absl::InvalidArgumentError(absl::StrCat(
          where(), "expected \"t x y z [qw qx qy qz [buttons]]\", got ", tok.size(), " fields"));
    }
    double v[8] = {0, 0, 0, 0, 1, 0, 0, 0};
    for (size_t i = 0; i < std::min<size_t>(tok.size(), 8); ++i) {
      if (!absl::SimpleAtod(tok[i], &v[i]) || !std::isfinite(v[i])) {
        return absl::InvalidArgumentError(
            absl::StrCat(where(), "field ", i + 1, " (\"", tok[i], "\") is not a finite number"));
      }
    }
    Key k;
    k.t = v[0];
    k.x = {v[1], v[2], v[3]};
    k.q = Eigen::Quaterniond(v[4], v[5], v[6], v[7]);
    if (tok.size() == 8 || tok.size() == 9) {
      if (k.q.norm() == 0) {
        return absl::InvalidArgumentError(absl::StrCat(where(), "zero quaternion"));
      }
      k.q.normalize();
    }
    if (tok.size() == 9 && !absl::SimpleAtoi(tok[8], &k.buttons)) {
      return absl::InvalidArgumentError(absl::StrCat(where(), "buttons must be an integer"));
    }
    if (!keys.empty() && !(k.t > keys.back().t)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where(), "t = ", k.t, " must be after the previous key's ", keys.back().t));
    }
    keys.push_back(k);
  }
  if (keys.empty()) return absl::InvalidArgumentError(absl::StrCat(origin, ": no keys"));
  return Trajectory(std::move(keys));
}

absl::StatusOr<Trajectory> Trajectory::Load(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot read ", path));
  std::stringstream ss;
  ss << in.rdbuf();
  return Parse(ss.str(), path);
}

Trajectory::Key Trajectory::At(double t) const {
  if (t <= keys_.front().t) return keys_.front();
  if (t >= keys_.back().t) return keys_.back();
  const auto it = std::upper_bound(keys_.begin(), keys_.end(), t,
                                   [](double v, const Key& k) { return v < k.t; });
  const Key& b = *it;
  const Key& a = *(it - 1);
  const double s = (t - a.t) / (b.t - a.t);
  Key k;
  k.t = t;
  k.x = (1 - s) * a.x + s * b.x;
  k.q = a.q.slerp(s, b.q);
  k.buttons = a.buttons;
  return k;
}

Eigen::Vector3d Trajectory::VelocityAt(double t) const {
  if (t < keys_.front().t || t >= keys_.back().t) return Eigen::Vector3d::Zero();
  const auto it = std::upper_bound(keys_.begin(), keys_.end(), t,
                                   [](double v, const Key& k) { return v < k.t; });
  const Key& b = *it;
  const Key& a = *(it - 1);
  return (b.x - a.x) / (b.t - a.t);
}

DeviceState TrajectoryDevice::Read(double t) {
  const Trajectory::Key k = trajectory_.At(t);
  DeviceState s;
  s.position = k.x;
  s.velocity = trajectory_.VelocityAt(t);
  s.orientation = k.q;
  s.buttons = k.buttons;
  s.device_time_us = static_cast<int64_t>(std::llround(t * 1e6));
  return s;
}

VirtualHand::VirtualHand(Trajectory target, DeviceParams params)
    : target_(std::move(target)), params_(params) {
  x_ = target_.At(0).x;
  v_.setZero();
  target_now_ = x_;
}

DeviceState VirtualHand::Read(double t) {
  // Advance from t_ to t with the force held.
  double remaining = std::max(0.0, t - t_);
  const int n = std::max(1, static_cast<int>(std::ceil(remaining / 1e-4)));
  const double dt = remaining / n;
  const double m = params_.hand_mass, k = params_.hand_stiffness, b = params_.damping;
  for (int i = 0; i < n && dt > 0; ++i) {
    const double ti = t_ + (i + 1) * dt;
    const Eigen::Vector3d target = target_.At(ti).x;
    const Eigen::Vector3d a = (k * (target - x_) - b * v_ + force_) / m;
    v_ += dt * a;
    x_ += dt * v_;
  }
  t_ = std::max(t_, t);
  const Trajectory::Key key = target_.At(t);
  target_now_ = key.x;
  DeviceState s;
  s.position = x_;
  s.velocity = v_;
  s.orientation = key.q;
  s.buttons = key.buttons;
  s.device_time_us = static_cast<int64_t>(std::llround(t * 1e6));
  return s;
}

absl::StatusOr<std::unique_ptr<Device>> MakeDevice(const std::string& kind, const std::string& path,
                                                   const DeviceParams& params) {
  if (kind == "trajectory" || kind == "virtual_hand") {
    absl::StatusOr<Trajectory> t = Trajectory::Load(path);
    if (!t.ok()) return t.status();
    if (kind == "trajectory") return std::make_unique<TrajectoryDevice>(*std::move(t), params);
    return std::make_unique<VirtualHand>(*std::move(t), params);
  }
  // A real backend registers here, e.g.
  //   #ifdef DYNSOLID_HAPTIC_HD
  //   if (kind == "hd") return MakeHdDevice(params);   // device_hd.cc
  //   #endif
  return absl::InvalidArgumentError(absl::StrCat("--device: unknown device \"", kind,
                                                 "\" (this build has: trajectory, virtual_hand)"));
}

}  // namespace dynsolid::haptic
