// The load set: what a person puts on a solid and takes off again (point
// forces, follower pressures, gravity, drags and curves, fixed regions),
// each under an id from one counter, with where each acts (its material
// point and control row, its selected quads, its held control points) and
// the forces that do not depend on the positions.
//
// A part of Solid with its own state (docs/architecture.md "The solid's
// parts"): it keeps and counts; Solid locates. Finding a material point, a
// control row or a region's points needs the solid's geometry, so Solid
// does that and hands the result in; the set never sees the mesh, the
// material or the integrator.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "dynsolid/scene.pb.h"
#include "solver/mesh/points.h"

namespace dynsolid::solid {

// A material point: an element and its parametric coordinates.
struct MaterialLocation {
  int kind = 0;
  int32_t element = 0;
  Eigen::Vector3d uvw;
};

class LoadSet {
 public:
  // A control point's weight in a material point, ascending by control
  // point: the point's position is sum w p_i.
  using ControlWeights = std::vector<std::pair<int32_t, double>>;

  struct PointLoad {
    int64_t id = 0;
    PointForce msg;
    MaterialLocation at;
    // The control row of `at`, made when first needed
    // (RebuildConstantForces) and carried by a restore that keeps the point
    // (KnownPoints): a cache, so filled in on a const set.
    mutable std::shared_ptr<const ControlWeights> row = nullptr;
  };
  struct PressureLoad {
    int64_t id = 0;
    Pressure msg;
    std::vector<int32_t> quads;  // selected surface quads
  };
  struct FixConstraint {
    int64_t id = 0;
    Region region;
    std::vector<int32_t> points;  // control points, ascending
  };
  // A drag, or a curve (several springs under one id): spring s pulls the
  // material point x_s = rows[s] . p towards targets[s] with force
  // stiffness (targets[s] - x_s).
  struct DragLoad {
    int64_t id = 0;
    bool curve = false;
    Drag drag;        // a drag's message (target kept current)
    CurveDrag shape;  // a curve's message (targets kept current)
    double stiffness = 0;
    std::vector<Eigen::Vector3d> material;  // rest positions of the springs' points
    std::vector<Eigen::Vector3d> targets;
    std::vector<ControlWeights> rows;
  };

  // Everything a set holds but its held positions and what follows from
  // the lists, as plain data: what a saved state or a topology edit carries
  // over (ids kept, each list ascending by id, every id below next_id).
  struct Contents {
    int64_t next_id = 1;
    Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
    std::vector<PointLoad> point_loads;
    std::vector<PressureLoad> pressures;
    std::vector<FixConstraint> fixes;
    std::vector<DragLoad> drags;
  };

  LoadSet() = default;
  // A set over control points held at `held`'s rows where a fix takes them
  // (one row per control point). The fix counts follow from c.fixes.
  LoadSet(Contents c, Points held);

  const std::vector<PointLoad>& point_loads() const { return c_.point_loads; }
  const std::vector<PressureLoad>& pressures() const { return c_.pressures; }
  const std::vector<FixConstraint>& fixes() const { return c_.fixes; }
  const std::vector<DragLoad>& drags() const { return c_.drags; }
  const Eigen::Vector3d& gravity() const { return c_.gravity; }
  bool has_gravity() const { return c_.gravity.squaredNorm() > 0; }
  int64_t next_id() const { return c_.next_id; }

  // ---- The fixed set: per control point, how many fixes hold it, and
  // where a held point is held.
  const std::vector<int32_t>& fix_count() const { return fix_count_; }
  bool held(int32_t i) const { return fix_count_[i] > 0; }
  const Points& held_at() const { return held_at_; }
  // The fixed set as flags (1: held).
  std::vector<uint8_t> FixedFlags() const;

  // ---- Edits. Each takes the next id and returns it.
  int64_t Add(PointLoad load);
  int64_t Add(PressureLoad load);
  int64_t Add(DragLoad load);
  // A fix of `points` (ascending, not empty): points it holds first are
  // held where `p` has them, and listed in *newly_held.
  int64_t AddFix(Region region, std::vector<int32_t> points, const Points& p,
                 std::vector<int32_t>* newly_held = nullptr);
  void SetGravity(const Eigen::Vector3d& g) { c_.gravity = g; }
  // Which list a load id was taken from (kNone: none has it).
  enum class Kind { kNone, kPointForce, kPressure, kDrag };
  Kind RemoveLoad(int64_t id);
  // The fix counts with fix `id` removed (it must be one of fixes()).
  std::vector<int32_t> CountsWithout(int64_t id) const;
  // Removes fix `id`; false when there is none.
  bool RemoveFix(int64_t id);
  const FixConstraint* FindFix(int64_t id) const;
  DragLoad* FindDrag(int64_t id);

  // ---- Ids, for listings and error messages.
  std::vector<int64_t> LoadIds() const;        // ascending
  std::vector<int64_t> ConstraintIds() const;  // ascending
  // "point forces: 1, 4; pressures: none; drags: 2".
  std::string DescribeLoadIds() const;
  std::string DescribeConstraintIds() const;  // "3, 5" or "none"

  // ---- Forces.
  // The constant forces (point forces, in id order, then gravity) over nc
  // control points: a point force's control row from `row_at` where it has
  // none yet; gravity as `gravity_mass` (the control-space mass per unit
  // acceleration, asked for only when there is gravity) times g.
  void RebuildConstantForces(
      int64_t nc, const std::function<ControlWeights(const MaterialLocation&)>& row_at,
      const std::function<const Eigen::VectorXd&()>& gravity_mass);
  bool has_constant_force() const { return has_constant_; }
  const Points& constant_forces() const { return constant_; }  // nc x 3 when has_constant_force
  // out += the drag springs' forces at p.
  void AddDragForces(const Points& p, Points& out) const;

  // Rest positions these loads have located (bit for bit), so that a
  // restore (an undo) locates again only the points it does not have.
  struct KnownPoints {
    using Key = std::array<uint64_t, 3>;
    static Key KeyOf(const Eigen::Vector3d& x);
    // Point forces' locations (snap setting applied) and control rows.
    std::map<Key, std::pair<MaterialLocation, std::shared_ptr<const ControlWeights>>> forces;
    std::map<Key, const ControlWeights*> rows;  // drag springs' control rows
  };
  KnownPoints CurrentPoints() const;  // valid while this set is unchanged

 private:
  Contents c_;
  std::vector<int32_t> fix_count_;
  Points held_at_;
  bool has_constant_ = false;
  Points constant_;
};

}  // namespace dynsolid::solid
