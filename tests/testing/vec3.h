// Coordinates into a dynsolid.Vec3 message, for tests that build requests.
#pragma once

#include "dynsolid/scene.pb.h"

namespace dynsolid::testing {

inline void SetXyz(Vec3* v, double x, double y, double z) {
  v->set_x(x);
  v->set_y(y);
  v->set_z(z);
}

}  // namespace dynsolid::testing
