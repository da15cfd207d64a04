// Clay: plastic flow of the rest shape, per control cell, for the
// corotational model with one frame per control cell (a part of the solid
// with its own state; models/cell_corotation.h CellFlow is its hook).
//
// Each control cell c carries plastic offsets u_p (its rest shape moved,
// 3 per control point of its support, rest frame) and an accumulated
// plastic strain alpha_c. After every explicit sub-step (and every implicit
// step) the force pass hands each cell its elastic local displacement u and
// K_c u, and the flow law moves the rest shape toward the deformed one:
//
//   W = 1/2 u . K_c u,  eps = sqrt(2 W / s_c)   (equivalent strain),
//   y = yield_strain + hardening * alpha_c      (yield strain now),
//   if eps > y:  lambda = (1 - y / eps) / (1 + hardening) * min(1, flow_rate * dt),
//                u_p += lambda u,  alpha_c += lambda eps,
//                dissipation += lambda u . K_c u  (>= 0).
//
// s_c is the cell's stiffness scale E V: twice the energy of a unit uniaxial
// stress state u = X_x e_x - nu (X_y e_y + X_z e_z) about its centre,
// averaged over the three axes (exactly E V for a homogeneous cell), so that
// eps is the strain of a bar in tension. With flow_rate * dt >= 1 the
// elastic strain returns to the yield surface in one step (the return
// mapping of linear hardening: eps - d = yield + hardening (alpha + d));
// a smaller rate flows the excess out over about 1 / flow_rate seconds. A bar stretched to eps_t and held yields a permanent set of
// (eps_t - yield) / (1 + hardening) once released. Rigid motion gives
// u = 0: it never yields. Below yield nothing changes: the solid is elastic.
//
// Determinism: a cell's update reads and writes its own entries only, so
// the pass's threads give the same bits for any thread count.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/models/cell_corotation.h"

namespace dynsolid::material {

// A cell's flow law (scene.proto Material's yield_strain, flow_rate,
// hardening; resolved: rate > 0) and the Poisson ratio its scale uses.
struct FlowLaw {
  double yield = 0;      // dimensionless; 0: never yields
  double rate = 0;       // 1/s
  double hardening = 0;  // dimensionless
  double poisson = 0.3;
  bool operator==(const FlowLaw&) const = default;
};

// The flow law of a resolved material (scene_loader.h ResolvedMaterial).
FlowLaw FlowLawOf(const Material& resolved);

class CellPlasticity : public models::CellFlow {
 public:
  // One law per control cell.
  explicit CellPlasticity(std::vector<FlowLaw> laws);

  // Hooks into `model` (a model of this solid's control cells), computing
  // the cells' scales from its matrices; again after every material change.
  void Attach(models::CellCorotation& model);

  // The next force pass flows over dt seconds (Arm), or not (Disarm).
  void Arm(double dt) { dt_ = dt; }
  void Disarm() { dt_ = 0; }

  // CellFlow.
  const double* offsets() const override { return offsets_.empty() ? nullptr : offsets_.data(); }
  bool flowing() const override { return dt_ > 0; }
  bool plastic(int32_t cell) const override { return active_[cell] != 0; }
  void Flow(int32_t cell, const double* u, const double* ku) override;

  bool any_yields() const;
  const std::vector<FlowLaw>& laws() const { return laws_; }
  // New laws (a paint): same count.
  void set_laws(std::vector<FlowLaw> laws);
  double alpha(int32_t cell) const { return alpha_.empty() ? 0.0 : alpha_[cell]; }
  // The plastic dissipation so far, J (per cell, summed in cell order).
  double dissipation() const;
  // Cells that have yielded (alpha > 0).
  int32_t yielded_cells() const;
  // The offsets as a control-point displacement: each control point's
  // offsets averaged over the cells that hold it (#control x 3), for a bake
  // or a topology edit that moves the plastic rest shape into the mesh.
  Points RestDisplacement(const models::CellCorotation& model, int64_t controls) const;

  // State: laws, offsets, alpha and dissipation, as bytes and back; Parse
  // checks the bytes against this solid's cells and entries (DataLoss
  // naming what is wrong) without changing anything.
  struct State {
    std::vector<FlowLaw> laws;
    std::vector<double> offsets, alpha, dissipation;
  };
  std::string SaveState() const;
  absl::StatusOr<State> ParseState(std::string_view bytes) const {
    return ParseState(bytes, static_cast<int32_t>(laws_.size()), entries_);
  }
  // The same for a solid of `cells` control cells whose cells' supports
  // have `entries` entries in all (no part made yet).
  static absl::StatusOr<State> ParseState(std::string_view bytes, int32_t cells, int64_t entries);
  void set_state(State s);
  // The stability guard's rollback.
  void Checkpoint();
  void Rollback();

 private:
  std::vector<FlowLaw> laws_;
  std::vector<double> scale_;           // s_c = E V per cell
  std::vector<int32_t> first_, size_;   // support ranges per cell (the model's)
  int64_t entries_ = 0;
  std::vector<double> offsets_;         // empty until the first flow
  std::vector<double> alpha_, dissipation_;
  // Per cell: its law yields or it has flowed (offsets not all zero).
  std::vector<uint8_t> active_;
  void UpdateActive();
  double dt_ = 0;
  State checkpoint_;
};

}  // namespace dynsolid::material
