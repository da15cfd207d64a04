// Haptic devices for dynsolid-haptic-bridge (docs/haptic.md "Devices").
//
// A Device is read and written once per tick by the bridge's 1 kHz loop,
// on the loop's thread: Read must not block (a real device's driver
// callback or a shared-memory sample; a simulated one integrates), Write
// hands the force on. Positions are in the scene's frame (metres), forces
// in newtons on the device (a real backend scales its workspace and
// forces into these units).
//
// Simulated devices (for tests, the benchmark and the main job):
//  - TrajectoryDevice: a scripted trajectory of poses, open loop (the
//    forces are recorded, they do not move it);
//  - VirtualHand: a hand of mass m on a spring k and damper b driven
//    towards a scripted target, so the loop is closed: the rendered force
//    pushes the hand back, and b is the device's physical damping that the
//    passivity bound uses.
//
// A real device backend (a PHANToM / OpenHaptics HD, a Force Dimension
// DHD, ...) goes into device_<name>.cc, implementing Device, registered in
// MakeDevice, and built only when CMake finds its library (see
// clients/haptic/CMakeLists.txt: DYNSOLID_HAPTIC_HD_LIBRARY); none is
// required to build or test dynsolid.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace dynsolid::haptic {

struct DeviceState {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();  // m/s
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  uint32_t buttons = 0;
  int64_t device_time_us = 0;  // the device's clock
};

class Device {
 public:
  virtual ~Device() = default;
  virtual std::string name() const = 0;
  // The state at loop time t (seconds since the loop started).
  virtual DeviceState Read(double t) = 0;
  // The force to render from now on (newtons, on the device).
  virtual void Write(const Eigen::Vector3d& force, double t) = 0;
  // The device's physical damping b (N s/m) and largest force (N): the
  // passivity bound and the force clamp use them.
  virtual double physical_damping() const = 0;
  virtual double max_force() const = 0;
  // A scripted device ends with its script (the bridge then stops).
  virtual bool Finished(double t) const { return false; }
  // Its script's length, seconds (0: none).
  virtual double duration() const { return 0; }
};

// A polyline in time read from a file: one line per key,
//   t x y z [qw qx qy qz [buttons]]
// (seconds, metres; '#' starts a comment), t strictly increasing; held at
// the last key after it. Errors name the file and line.
class Trajectory {
 public:
  struct Key {
    double t = 0;
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    uint32_t buttons = 0;
  };
  static absl::StatusOr<Trajectory> Parse(const std::string& text, const std::string& origin);
  static absl::StatusOr<Trajectory> Load(const std::string& path);
  explicit Trajectory(std::vector<Key> keys) : keys_(std::move(keys)) {}
  Key At(double t) const;
  Eigen::Vector3d VelocityAt(double t) const;
  double duration() const { return keys_.empty() ? 0 : keys_.back().t; }
  const std::vector<Key>& keys() const { return keys_; }

 private:
  std::vector<Key> keys_;
};

struct DeviceParams {
  double damping = 20.0;    // b, N s/m
  double max_force = 40.0;  // N
  // VirtualHand: mass (kg) and the spring to the target (N/m).
  double hand_mass = 0.5;
  double hand_stiffness = 2000.0;
};

class TrajectoryDevice final : public Device {
 public:
  TrajectoryDevice(Trajectory trajectory, DeviceParams params)
      : trajectory_(std::move(trajectory)), params_(params) {}
  std::string name() const override { return "trajectory"; }
  DeviceState Read(double t) override;
  void Write(const Eigen::Vector3d& force, double t) override { last_force_ = force; }
  double physical_damping() const override { return params_.damping; }
  double max_force() const override { return params_.max_force; }
  bool Finished(double t) const override { return t > trajectory_.duration(); }
  double duration() const override { return trajectory_.duration(); }

 private:
  Trajectory trajectory_;
  DeviceParams params_;
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
};

// m x'' = k (target(t) - x) - b x' + F: integrated with the force held
// over each interval between Reads (semi-implicit Euler in sub-steps of at
// most 0.1 ms, so it is accurate whatever the loop's period jitter).
class VirtualHand final : public Device {
 public:
  VirtualHand(Trajectory target, DeviceParams params);
  std::string name() const override { return "virtual_hand"; }
  DeviceState Read(double t) override;
  void Write(const Eigen::Vector3d& force, double t) override { force_ = force; }
  double physical_damping() const override { return params_.damping; }
  double max_force() const override { return params_.max_force; }
  bool Finished(double t) const override { return t > target_.duration(); }
  double duration() const override { return target_.duration(); }
  const Eigen::Vector3d& target_now() const { return target_now_; }

 private:
  Trajectory target_;
  DeviceParams params_;
  Eigen::Vector3d x_, v_;
  Eigen::Vector3d force_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_now_ = Eigen::Vector3d::Zero();
  double t_ = 0;
};

// "trajectory" or "virtual_hand" with the script at `path`; the place a
// real backend is added (device.cc).
absl::StatusOr<std::unique_ptr<Device>> MakeDevice(const std::string& kind, const std::string& path,
                                                   const DeviceParams& params);

}  // namespace dynsolid::haptic
