// The one interface both stiffness models share (docs/model.md section 4): the
// integrators only ever ask for g(d), the internal forces on the FEM nodes.
#pragma once

#include <array>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "solver/common/worker_pool.h"
#include "solver/mesh/points.h"

namespace dynsolid::models {

// Models split their per-step loops into this many fixed parts, whatever
// the number of threads, and add the parts' sums in part order: results are
// bit-identical for any thread count.
inline constexpr int kForceParts = 8;

class InternalForceModel {
 public:
  virtual ~InternalForceModel() = default;

  // g (#nodes by 3, newtons) = internal forces at node positions d (#nodes
  // by 3, metres); returns the strain energy (joules). Updates the model's
  // per-element frames (warm starts), so calls must follow the motion.
  // Allocates nothing after the first call.
  virtual double Forces(const Points& d, Points& g) = 0;

  // The same in full double precision, for callers that difference or
  // compare forces and energies (finite differences, the stable-step
  // estimate, diagnostics), where a model steps with single-precision
  // element products (LocalFrameModel). Updates the frames as Forces does.
  virtual double ExactForces(const Points& d, Points& g) { return Forces(d, g); }

  // Forget warm-started frames (after a rollback or a jump in state).
  virtual void ResetFrames() = 0;

  // The warm-started element frames, per kind (cubic, linear, pyramid), one
  // unit quaternion per element of ElementLayout::blocks[kind]: part of a
  // solid's exact state (saved and restored bit for bit) and handed over to
  // a model rebuilt after a material change. set_frames needs the sizes of
  // frames(). (A copy: a model may keep them in another order.)
  using Frames = std::array<std::vector<Eigen::Quaterniond>, 3>;
  virtual Frames frames() const = 0;
  virtual void set_frames(const Frames& frames) = 0;

  virtual std::string_view name() const = 0;

  // The threads its passes run on from now on (a model built on a thread
  // pool of its own, off a solid's simulation thread, moves to the solid's
  // when installed; the results do not depend on the pool's size).
  virtual void set_pool(WorkerPool& pool) = 0;

  // Wall time of the last Forces call's parts, milliseconds: the
  // deformation measure (-1 when the model has none) and the element loop.
  struct Timing {
    double measure_ms = -1;
    double elements_ms = 0;
  };
  virtual Timing last_timing() const = 0;
};

}  // namespace dynsolid::models
