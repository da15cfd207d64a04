// What the load clients' commands aim at: the solid's rest box and
// control-cell size (Inspect), material points inside it (Pick), and each
// client's seeded mix of points, sizes and kinds.
#pragma once

#include <chrono>
#include <cstdint>
#include <random>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::load {

Vec3 V(double x, double y, double z);

// A call with retries while the server is away (a restart fault).
template <typename Fn>
grpc::Status Retrying(Fn fn, double seconds = 30) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    const grpc::Status s = fn();
    if (s.error_code() != grpc::StatusCode::UNAVAILABLE || Clock::now() > deadline) return s;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

// The bounding box of the scene's solid at rest, for the commands' points:
// from Inspect (control mesh rest positions).
struct Box {
  double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  // Material points inside the solid (rest positions), for the commands
  // that name one (MaterialPoints); empty: points in the box.
  std::vector<Vec3> inside;
  // The control mesh's mean edge length at rest: a control cell's size.
  double cell = 1;
};

absl::StatusOr<Box> RestBox(Sessions::Stub& stub, const SessionRef& ref);

// Rest positions inside the solid, `count` of them at most. On vertical
// lines at random (x, y) over the box: the material points where a ray
// from above and a ray from below first hit the surface (Pick, on the
// solid at rest), and a point at random between them. That point is kept
// when a ray cast up from it first hits the top hit (it lies in the part
// the top hit belongs to), else the top hit itself. Lines that miss the
// solid are skipped. A box of a scene (the chair) is mostly empty: points
// drawn in it fall outside the solid and their commands are refused,
// which then says nothing about the server.
std::vector<Vec3> MaterialPoints(Sessions::Stub& stub, const SessionRef& ref, const Box& box,
                                 int count, uint64_t seed);

// One client's seeded command mix: material points from Box::inside,
// targets in the upper part of the box (where nothing is pinned by the
// scenes), sizes in control cells.
class Mix {
 public:
  Mix(uint64_t seed, const Box& box, bool edits) : rng_(seed), box_(box), edits_(edits) {}

  // A material point inside the solid (Box::inside), or in the box.
  Vec3 Material() {
    if (box_.inside.empty()) return Inside();
    return box_.inside[Index(box_.inside.size())];
  }
  Vec3 Inside(double top_fraction = 0.5) {
    std::uniform_real_distribution<double> u(0.2, 0.8), t(1 - top_fraction * 0.6, 0.95);
    const double x = box_.lo[0] + u(rng_) * (box_.hi[0] - box_.lo[0]);
    const double y = box_.lo[1] + u(rng_) * (box_.hi[1] - box_.lo[1]);
    const double z = box_.lo[2] + t(rng_) * (box_.hi[2] - box_.lo[2]);
    return V(x, y, z);
  }
  double Size() const { return box_.hi[2] - box_.lo[2]; }
  // A control cell's size, metres (block3's: 1).
  double Cell() const { return box_.cell; }
  double Uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  int Pick(const std::vector<double>& weights) {
    std::discrete_distribution<int> d(weights.begin(), weights.end());
    return d(rng_);
  }
  size_t Index(size_t n) { return std::uniform_int_distribution<size_t>(0, n - 1)(rng_); }
  bool edits() const { return edits_; }

 private:
  std::mt19937_64 rng_;
  Box box_;
  bool edits_;
};

}  // namespace dynsolid::load
