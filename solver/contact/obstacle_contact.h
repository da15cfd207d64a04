// A floor and static obstacles (scene.proto Environment) the solid's
// boundary surface rests on and bumps into: a part of the solid with its own
// state (the vertices in contact, with their entry planes and friction
// anchors), given the surface rows of the node matrix and asked for forces.
//
// The surface: vertices x_n = S_n p (S the boundary vertices' rows of the
// node matrix A; p the control points). A vertex that enters an obstacle
// gets a penalty force along the normal of the plane it entered through,
//
//   depth d = o - n . x  (> 0 inside),  f_N = max(0, k_n d - c_n n . v),
//
// k_n the vertex's stiffness (below), c_n = 2 zeta k_n / omega_c, and
// Coulomb friction as a stick spring of the same stiffness to an anchor
// on the plane: f_T = -k_n (x - a)_T - c_n v_T, capped at mu f_N; past the
// cap the vertex slides and its anchor follows (docs/model.md "Contact").
// A touch ends when its vertex rises a hundredth of the vertex spacing
// above its plane (no force above the plane: no adhesion), so that a
// vertex trembling on the floor keeps its anchor. The control forces are
// S^T f. The entry plane
// is fixed when the contact starts: for the floor its plane, for a box the
// face the vertex's path over the sub-step crossed first (so a vertex
// moving fast enough to reach the far side of a box within one sub-step is
// still pushed back the way it came: no tunnelling), for a ball the
// tangent plane at the point nearest the vertex (found again each time).
//
// Stiffness: the stiffest the sub-step carries. Each vertex's stiffness is
// k_n = scale w_n, w_n the least, over the control points of its row, of a
// point's lumped mass over the weight all vertices lean on it with (so
// that, by Gershgorin on the lumped system, no light corner of the surface
// limits the rest), and scale puts the contact's highest frequency with
// every vertex in contact, omega_c = sqrt(scale lambda) (lambda the
// largest eigenvalue of (S^T diag(w) S) u = lambda Mt u, by power
// iteration at build), at 0.6 / h_sub: stable for the explicit force
// (central differences, and backward Euler's, which takes contact
// explicitly) with its damping. The solid's own sub-steps set h_sub; they
// rise only when the total stiffness would stay below `stiffness` E / L
// per square metre of surface (scene.proto Environment.stiffness, default
// 10; E the mean Young's modulus, L the solid's size): an impact at speed
// v sinks about 2.4 v L / (stiffness c), c = sqrt(E / rho) (measured on a
// dropped block).
//
// Culling: the vertices are grouped by control cell; a group is looked at
// only when the box around its control points (at the sub-step's start and
// end) reaches an obstacle. Every row of S is a convex combination of
// control points (subdivision weights are non-negative and sum to one;
// checked at build, else no group is skipped), so a vertex lies in that box.
//
// Determinism: vertices and obstacles are visited in a fixed order and the
// state changes only in AddForces(); the same positions and state give the
// same bits.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/mesh/points.h"

namespace dynsolid::contact {

// What the solid gives the environment to build against.
struct SurfaceInput {
  // The boundary vertices' rows of the node matrix (#surface x #control).
  const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>* rows = nullptr;
  // Outward quads over the surface vertices (a triangle as (a, b, c, c)).
  const std::vector<std::array<int32_t, 4>>* quads = nullptr;
  // Per quad, the group it belongs to (e.g. its control cell); -1: none.
  const std::vector<int32_t>* quad_group = nullptr;
  // The surface vertices at rest (#surface x 3).
  const Points* rest = nullptr;
};

class ObstacleContact {
 public:
  // Obstacle kinds, in scene order after the floor.
  struct Shape {
    enum Kind { kPlane, kBox, kSphere } kind = kPlane;
    Eigen::Vector3d a = Eigen::Vector3d::Zero();  // plane point, box min, ball centre
    Eigen::Vector3d b = Eigen::Vector3d::Zero();  // plane unit normal, box max
    double radius = 0;                            // ball
  };
  // One vertex touching one obstacle.
  struct Touch {
    int32_t vertex = 0;
    int32_t obstacle = 0;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // entry plane: n . y = offset
    double offset = 0;
    Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // friction anchor (on the plane)
  };
  // Checks the environment (InvalidArgument naming the field, e.g.
  // "environment.obstacles[1].sphere.radius must be > 0") and builds the
  // vertex groups. Null with OK status when the environment is empty.
  static absl::StatusOr<std::unique_ptr<ObstacleContact>> Create(const Environment& env,
                                                                 const SurfaceInput& surface);
  static absl::Status Validate(const Environment& env, std::string_view field);

  // Sets the penalty stiffness for a solid of mean Young's modulus `young`
  // (Pa) and control mass matrix mt stepped by h (seconds) in `substeps`
  // sub-steps, as the header says, and returns the sub-steps it needs
  // (at least `substeps`, at most max_substeps).
  int Calibrate(const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>& mt, double young,
                double h, int substeps, int max_substeps);
  // The mean stiffness per square metre of surface, N/m^3.
  double kappa() const { return kappa_; }
  int min_substeps() const { return min_substeps_; }

  // The contact forces on the control points at p, the vertices' velocities
  // taken as (x(p) - x(prev)) / h, added to `out` (#control x 3).
  // Updates the contacts (new ones, releases, friction anchors): the state
  // is that of p afterwards. Allocates nothing once warmed up.
  void AddForces(const Points& p, const Points& prev, double h, Points& out);
  // The largest penetration (metres) over the vertices in contact, as of the
  // last AddForces().
  double max_depth() const { return max_depth_; }
  const std::vector<Touch>& touches() const { return touches_; }
  const std::vector<Shape>& obstacles() const { return obstacles_; }
  int32_t groups_checked() const { return groups_checked_; }

  // The state (the touches) as bytes, and back. Restore checks the bytes
  // against this surface and obstacle count (DataLoss naming what is wrong)
  // and changes nothing on error.
  std::string SaveState() const;
  absl::StatusOr<std::vector<Touch>> ParseState(std::string_view bytes) const;
  void set_touches(std::vector<Touch> touches) { touches_ = std::move(touches); }
  absl::Status RestoreState(std::string_view bytes);
  // For the stability guard's rollback: Checkpoint keeps a copy of the
  // touches (in a buffer of its own, reused), Rollback takes it back.
  void Checkpoint() { checkpoint_ = touches_; }
  void Rollback() { touches_ = checkpoint_; }

 private:
  ObstacleContact() = default;
  void BuildGroups(const SurfaceInput& s);
  // The box around group g's control points at p and prev, and whether a
  // box can reach obstacle o (always, when culling is not exact).
  void GroupBox(int32_t g, const Points& p, const Points& prev, Eigen::Vector3d& lo,
                Eigen::Vector3d& hi) const;
  bool BoxMayTouch(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int32_t o) const;
  Eigen::Vector3d VertexAt(int32_t v, const Points& p) const;
  // A new touch of vertex v (at x, from x_prev) with obstacle o, if it is
  // inside it or its path crossed it.
  bool Begin(int32_t v, int32_t o, const Eigen::Vector3d& x, const Eigen::Vector3d& x_prev,
             Touch& t) const;
  // Whether touch t still holds at x (updates a ball's plane).
  bool Holds(Touch& t, const Eigen::Vector3d& x) const;

  std::vector<Shape> obstacles_;
  double friction_ = 0, damping_ratio_ = 0.5, stiffness_ = 10;
  // Surface rows in CSR form.
  std::vector<int64_t> row_start_;
  std::vector<int32_t> row_col_;
  std::vector<double> row_val_;
  std::vector<double> area_;    // per vertex, m^2
  std::vector<double> weight_;  // per vertex: its stiffness per unit scale_ (kg)
  // Groups: their vertices and control points (CSR).
  std::vector<int64_t> group_vertex_start_, group_point_start_;
  std::vector<int32_t> group_vertex_, group_point_;
  bool convex_rows_ = true;  // every row a convex combination: culling is exact
  int64_t controls_ = 0;
  double kappa_ = 0, omega_ = 0, scale_ = 0, spacing_ = 0, release_ = 0, extent_ = 0;
  int min_substeps_ = 1;
  std::vector<Touch> touches_;  // ascending (vertex, obstacle)
  std::vector<Touch> next_;     // scratch
  std::vector<Touch> checkpoint_;
  std::vector<uint8_t> seen_;   // scratch: per (vertex, obstacle) of touches_
  double max_depth_ = 0;
  int32_t groups_checked_ = 0;
};

}  // namespace dynsolid::contact
