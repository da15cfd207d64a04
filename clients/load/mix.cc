#include "clients/load/mix.h"

#include <algorithm>
#include <cmath>

#include "clients/lib/channel.h"

namespace dynsolid::load {

Vec3 V(double x, double y, double z) {
  Vec3 v;
  v.set_x(x);
  v.set_y(y);
  v.set_z(z);
  return v;
}

absl::StatusOr<Box> RestBox(Sessions::Stub& stub, const SessionRef& ref) {
  InspectRequest r;
  *r.mutable_session() = ref;
  r.set_control_mesh(true);
  InspectReply reply;
  const grpc::Status s = Retrying([&] {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return stub.Inspect(&c, r, &reply);
  });
  if (!s.ok()) return client::ToAbslStatus(s, "Inspect");
  Box b;
  const auto& p = reply.control_mesh().rest_positions();
  for (int a = 0; a < 3; ++a) b.lo[a] = INFINITY, b.hi[a] = -INFINITY;
  for (int i = 0; i + 2 < p.size(); i += 3) {
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], p[i + a]);
      b.hi[a] = std::max(b.hi[a], p[i + a]);
    }
  }
  const auto& e = reply.control_mesh().edge_vertices();
  double length = 0;
  int edges = 0;
  for (int k = 0; k + 1 < e.size(); k += 2) {
    const int i = 3 * e[k], j = 3 * e[k + 1];
    if (j + 2 >= p.size() || i + 2 >= p.size()) continue;
    length += std::sqrt((p[i] - p[j]) * (p[i] - p[j]) + (p[i + 1] - p[j + 1]) * (p[i + 1] - p[j + 1]) +
                        (p[i + 2] - p[j + 2]) * (p[i + 2] - p[j + 2]));
    ++edges;
  }
  if (edges > 0 && length > 0) b.cell = length / edges;
  return b;
}

std::vector<Vec3> MaterialPoints(Sessions::Stub& stub, const SessionRef& ref, const Box& box,
                                 int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.05, 0.95), t(0.3, 0.7);
  std::vector<Vec3> out;
  auto pick = [&](double x, double y, double z, double dz, PickReply* reply) {
    PickRequest r;
    *r.mutable_session() = ref;
    *r.mutable_origin() = V(x, y, z);
    *r.mutable_direction() = V(0, 0, dz);
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    return stub.Pick(&c, r, reply).ok() && reply->hit();
  };
  const double margin = 1 + (box.hi[2] - box.lo[2]);
  for (int tries = 0; tries < 4 * count && static_cast<int>(out.size()) < count; ++tries) {
    const double x = box.lo[0] + u(rng) * (box.hi[0] - box.lo[0]);
    const double y = box.lo[1] + u(rng) * (box.hi[1] - box.lo[1]);
    PickReply down, up;
    // The first hits from above the box and from below it.
    if (!pick(x, y, box.hi[2] + margin, -1, &down)) continue;
    const double z0 = down.point().z();
    if (!pick(x, y, box.lo[2] - margin, 1, &up)) continue;
    const Vec3& a = down.material_point();
    const Vec3& b = up.material_point();
    // A point a fraction f of the way from the top hit to the bottom one
    // lies in the part hit from above when a ray cast up from it (at the
    // same fraction of the current heights) first hits the top hit;
    // otherwise another part hangs below that one, and the top hit itself
    // is kept.
    const double f = t(rng);
    Vec3 m = V(a.x() + f * (b.x() - a.x()), a.y() + f * (b.y() - a.y()),
               a.z() + f * (b.z() - a.z()));
    PickReply check;
    const double zm = z0 + f * (up.point().z() - z0);
    if (pick(x, y, zm, 1, &check) && std::abs(check.point().z() - z0) < 1e-6 * margin) {
      out.push_back(m);
    } else {
      out.push_back(a);
    }
  }
  return out;
}

}  // namespace dynsolid::load
