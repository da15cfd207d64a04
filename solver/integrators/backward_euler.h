// Backward Euler for stiff scenes (docs/model.md section 5), linearized at p(t)
// with the element frames held fixed for the step:
//
//   (Mt + h Dt + h^2 Kt) dv = h (F - h Kt v - Dt v),   v = (p - p_prev) / h,
//   v' = v + dv,   p(t+h) = p + h v',
//
// F = A^T (f - g(A p)), Kt x = A^T K (A x) (+ penalty springs) applied
// matrix-free through a callback. Solved by preconditioned CG on all three
// components at once (Kt couples them); the preconditioner is the incomplete
// Cholesky factor of Mt + h Dt per component, or, after
// SetStiffnessPreconditioner(K0), the sparse Cholesky factor of
// Mt + h Dt + h^2 K0 on the free DOFs with K0 the rest stiffness (the
// system itself at small rotations: a handful of iterations whatever the
// stiffness), made by CHOLMOD (ReducedCholesky: METIS or AMD order,
// supernodal factorization and solves; it replaced Eigen's
// SimplicialLDLT, whose solve was most of a step on large meshes).
//
// Warm start. CG starts from dv0 extrapolated linearly from the last two
// steps' dv (2 dv[n-1] - dv[n-2]; dv[n-1] after one step; zero after Setup
// or ResetWarmStart): under smooth motion dv changes slowly from step to
// step. On block3 (bench/implicit_bench: pull, twist, orbit) dv0 leaves a
// relative residual of about 5e-3 (2e-2 from dv[n-1] alone, 1 from zero),
// and one CG iteration from it about 4e-7, where two from zero left 2e-7:
// one element pass per step fewer. Its residual
//   r0 = b - S dv0 = h (F - h Kt (v + dv0) - Dt v) - (Mt + h Dt) dv0
// needs no Kt product of its own: with frames fixed the internal force is
// affine in p, so F - h Kt (v + dv0) = A^T (f - g_R(A (p + h (v + dv0)))),
// the force evaluated ahead along v + dv0 (Step with `force_ahead`: one
// element pass for the right-hand side and the start together). Step with
// `force` (the reference path) takes F - h Kt (v + dv0) from F and one Kt
// product.
//
// Stopping test: ||r|| <= tolerance * ||b - h^2 Kt dv0||, the right-hand side
// with the stiffness acting on the warm start left out (it is r0 + (Mt + h
// Dt) dv0: known without a product). From a cold start that is ||b||. From a
// warm start near the solution it is about ||(Mt + h Dt) dv||, the impulse
// that changes the velocity: below ||b|| = ||S dv|| where the stiffness
// term adds to it (stiff scenes: a stricter test), and at most about
// ||b|| / (1 - kTrustedStart) otherwise (for Mt and Kt that commute). A
// warm start that does not explain the right-hand side that well (||r0||
// above kTrustedStart of the scale: an abrupt change, a load switched)
// costs one Kt product: b = r0 + S dv0 exactly, the start is the better of
// dv0 and zero, and the scale is ||b||. Both Step overloads do the same, so
// they stop at the same iteration.
//
// Unconditionally stable for linear elasticity. Fixed control points keep
// their positions.
#pragma once

#include <functional>
#include <memory>

#include <Eigen/SparseCore>

#include "solver/integrators/cg.h"
#include "solver/integrators/reduced_cholesky.h"

namespace dynsolid::integrators {

class BackwardEuler {
 public:
  // out = Kt x (control space, #control by 3).
  using StiffnessOperator = std::function<void(const Points& x, Points& out)>;
  // out = F - h Kt w for a velocity w (#control by 3; fixed rows of w are
  // zero), i.e. the force at p + h w with the frames of p: the right-hand
  // side's force and the warm start's residual, folded (w = v + dv0).
  using ForceAhead = std::function<void(const Points& v, Points& out)>;

  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, double h, std::vector<uint8_t> fixed);

  // Setup's costly part (Mt + h Dt, its preconditioner and, with `k0`, the
  // stiffness preconditioner's factor), made from values alone: another
  // thread may make it while this integrator steps. Setup(mt, dt, prepared)
  // then gives the bits of Setup(mt, dt, h, fixed) followed by
  // SetStiffnessPreconditioner(*k0), for mt and dt equal to the ones given
  // here.
  struct Flat;
  struct Prepared {
    SparseMatrix md;
    std::vector<uint8_t> fixed;
    double h = 0;
    ColumnPreconditioner pre;  // made (pre_ready) only when flat is null
    bool pre_ready = false;
    std::shared_ptr<Flat> flat;
  };
  static Prepared Prepare(const SparseMatrix& mt, const SparseMatrix* dt, double h,
                          std::vector<uint8_t> fixed, const SparseMatrix* k0);
  void Setup(const SparseMatrix* mt, const SparseMatrix* dt, Prepared prepared);

  // One step from (p, p_prev) to p_next. `force` = F (then F - h Kt (v + dv0)
  // takes one Kt product) or `force_ahead` gives it directly; both then
  // solve the same system from the warm start dv0 with PCG to `tolerance`
  // (the stopping test above), at most `max_iterations`.
  CgStats Step(const Points& p, const Points& p_prev, const Points& force,
               const StiffnessOperator& kt, Points& p_next, double tolerance, int max_iterations);
  CgStats Step(const Points& p, const Points& p_prev, const ForceAhead& force_ahead,
               const StiffnessOperator& kt, Points& p_next, double tolerance, int max_iterations);

  // The last step's velocity change dv, the CG's correction c = dv - dv0 to
  // the warm start and Kt c (summed from the CG's own Kt products, no extra
  // evaluation): a caller's energy bookkeeping (E(p + h (v + dv)) of a
  // quadratic E from E and its gradient at the point p + h (v + dv0) the
  // folded force was evaluated at). Fixed rows are zero.
  const Points& last_dv() const { return x_; }
  const Points& last_correction() const { return c_; }
  const Points& last_kt_correction() const { return kx_; }

  // What the next warm start is made of: the last two steps' dv and how
  // many of them count (0, 1 or 2). Part of a solid's saved state (the same
  // history gives the same bits). Setup and ResetWarmStart clear it.
  struct History {
    Points last, before;  // dv[n-1], dv[n-2]: #control by 3
    int32_t steps = 0;    // 0, 1 or 2
  };
  const History& history() const { return history_; }
  // `h` must have #control rows and 0 to 2 steps (a caller reading it from
  // bytes checks that first).
  void set_history(History h);
  void ResetWarmStart();

  // K0: 3 #control square, DOFs 3 i + c (the layout of a row-major
  // #control by 3 Points). Call after Setup.
  void SetStiffnessPreconditioner(const SparseMatrix& k0);

  double h() const { return h_; }
  // Steps whose warm start was rechecked against the exact b (see above).
  int64_t rechecked_starts() const { return rechecked_starts_; }

  static constexpr double kTrustedStart = 0.1;

 private:
  void Apply(const StiffnessOperator& kt, const Points& x, Points& y);
  // Solves from x_ = dv0 and its residual r_ (set by the Step overloads, with
  // rhs_ = b - h^2 Kt dv0 for the stopping test) and writes p_next.
  CgStats Solve(const Points& p, const StiffnessOperator& kt, Points& p_next, double tolerance,
                int max_iterations);
  void Mask(Points& m) const;

  const SparseMatrix* mt_ = nullptr;
  const SparseMatrix* dt_ = nullptr;
  double h_ = 0;
  SparseMatrix md_;  // Mt + h Dt
  std::vector<uint8_t> fixed_;
  ColumnPreconditioner pre_;
  bool pre_ready_ = false;  // pre_ made (it is, whenever flat_ is null)
  std::shared_ptr<Flat> flat_;
  // The factor of md + h^2 K0 (fixed DOFs identity), or null when it fails.
  static std::shared_ptr<Flat> Factor(const SparseMatrix& md, const std::vector<uint8_t>& fixed,
                                      double h, const SparseMatrix& k0);
  void Precondition(const Points& r, Points& z) const;
  Points v_, rhs_, x_, r_, z_, p_, q_, tmp_, kx_, c_;
  History history_;
  int64_t rechecked_starts_ = 0;
  // x_ = dv0 from history_.
  void WarmStart();
};

}  // namespace dynsolid::integrators
