// The wire's Vec3 (scene.proto) from and to Eigen, for the server's replies
// and undo records.
#pragma once

#include <Eigen/Core>

#include "dynsolid/scene.pb.h"

namespace dynsolid::server {

inline Vec3 ToVec3(const Eigen::Vector3d& x) {
  Vec3 v;
  v.set_x(x.x());
  v.set_y(x.y());
  v.set_z(x.z());
  return v;
}

}  // namespace dynsolid::server
