// Clay: plastic flow of the rest shape, for the corotational model with
// one frame per control cell (models/cell_corotation.h CellFlow is its
// hook) or one frame per finite element (models/corotational.h
// ElementFlow). A part of the solid with its own state.
//
// The flow acts on units: the control cells of the per-cell model, or the
// finite elements of the per-element one. Each unit u carries plastic
// offsets u_p (its rest shape moved, 3 per point of its support: the
// cell's control points or the element's nodes, rest frame) and an
// accumulated plastic strain alpha_u. After every explicit sub-step (and
// every implicit step) the force pass hands each unit its elastic local
// displacement u and K u, and the flow law moves the rest shape toward the
// deformed one:
//
//   W = 1/2 u . K u,  eps = sqrt(2 W / s_u)     (equivalent strain),
//   y = yield_strain + hardening * alpha_u      (yield strain now),
//   if eps > y:  lambda = (1 - y / eps) / (1 + hardening) * min(1, flow_rate * dt),
//                u_p += lambda u,  alpha_u += lambda eps,
//                dissipation += lambda u . K u  (>= 0).
//
// s_u is the unit's stiffness scale E V. For a control cell: twice the
// energy of a unit uniaxial stress state u = X_x e_x - nu (X_y e_y + X_z
// e_z) about its centre, averaged over the three axes (exactly E V for a
// homogeneous cell); for an element, its mean sampled modulus times its
// rest volume (the same for a homogeneous element). So eps is the strain
// of a bar in tension. With flow_rate * dt >= 1 the elastic strain returns
// to the yield surface in one step (the return mapping of linear
// hardening: eps - d = yield + hardening (alpha + d)); a smaller rate flows
// the excess out over about 1 / flow_rate seconds. A bar stretched to
// eps_t and held yields a permanent set of (eps_t - yield) / (1 +
// hardening) once released. Rigid motion gives u = 0: it never yields.
// Below yield nothing changes: the solid is elastic.
//
// The flow laws are per control cell (a paint paints cells); an element
// takes its control cell's.
//
// Determinism: a unit's update reads and writes its own entries only, so
// the pass's threads give the same bits for any thread count.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/scene.pb.h"
#include "solver/models/cell_corotation.h"
#include "solver/models/corotational.h"

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

class Plasticity : public models::CellFlow, public models::ElementFlow {
 public:
  // One law per control cell.
  explicit Plasticity(std::vector<FlowLaw> laws);

  // Hooks into `model` (a model of this solid's control cells), computing
  // the cells' scales from its matrices; again after every material change.
  void Attach(models::CellCorotation& model);
  // Hooks into the per-element `model`; `control_cell` maps the layout's
  // level-L cells to control cells (empty: they are the control cells).
  // Again after every material change.
  void Attach(models::CorotationalModel& model, const std::vector<int32_t>& control_cell);

  // The units and support entries a model gives (for ParseState before any
  // part is made).
  struct Units {
    int32_t units = 0;
    int64_t entries = 0;
  };
  static Units UnitsOf(const models::CellCorotation& model);
  static Units UnitsOf(const models::ElementLayout& layout);

  // The next force pass flows over dt seconds (Arm), or not (Disarm).
  void Arm(double dt) { dt_ = dt; }
  void Disarm() { dt_ = 0; }

  // CellFlow.
  const double* offsets() const override { return offsets_.empty() ? nullptr : offsets_.data(); }
  bool flowing() const override { return dt_ > 0; }
  bool plastic(int32_t cell) const override { return active_[cell] != 0; }
  void Flow(int32_t cell, const double* u, const double* ku) override { FlowUnit(cell, u, ku); }
  // ElementFlow.
  const double* offsets(int kind, int32_t element) const override {
    const int32_t unit = base_[kind] + element;
    return active_[unit] != 0 ? offsets_.data() + 3 * static_cast<int64_t>(first_[unit]) : nullptr;
  }
  void Flow(int kind, int32_t element, const double* u, const double* ku) override {
    FlowUnit(base_[kind] + element, u, ku);
  }

  bool any_yields() const;
  const std::vector<FlowLaw>& laws() const { return laws_; }
  // New laws (a paint): same count.
  void set_laws(std::vector<FlowLaw> laws);
  // The largest accumulated plastic strain over control cell `cell`'s units.
  double alpha(int32_t cell) const;
  double max_alpha() const;
  // The plastic dissipation so far, J (per unit, summed in unit order).
  double dissipation() const;
  // Control cells that have yielded (some unit with alpha > 0).
  int32_t yielded_cells() const;
  // The offsets as a control-point displacement: each control point's
  // offsets averaged over the cells that hold it (#control x 3), for a bake
  // or a topology edit that moves the plastic rest shape into the mesh.
  // (Per-cell units only.)
  Points RestDisplacement(const models::CellCorotation& model, int64_t controls) const;

  // A topology edit's carry-over: new unit u takes `old`'s unit
  // source[u] (-1: none, it starts elastic at the mesh's rest shape), its
  // support entry a being the old unit's entry entry_map[u][a] (empty: the
  // same order). Its offsets, plastic strain and dissipation come along.
  // Returns the units carried. Laws are not touched (set_laws).
  int32_t CarryFrom(const Plasticity& old, const std::vector<int32_t>& source,
                    const std::vector<std::vector<int32_t>>& entry_map);
  // After CarryFrom, per control cell (per-cell units only): the cells a
  // topology edit changed (carried[c] < 0) get an estimate of the old
  // plastic rest shape instead of the mesh's. A cell with a source
  // (cell_source[c] >= 0) keeps the source's offsets at the points the two
  // share and takes, at its other points, the affine map that best fits
  // (least squares over rest positions) the source's offsets; a new cell
  // takes the old points' averaged offsets (RestDisplacement) where it has
  // old points and their affine fit elsewhere. Plastic strain comes from
  // the source (0 in a new cell); dissipation stays with the old units.
  // `point_source`: new control point -> old one (-1: new); rest positions
  // of the old and new control points. Returns the cells estimated.
  int32_t EstimateChanged(const Plasticity& old, const models::CellCorotation& old_model,
                          const models::CellCorotation& model, const Points& old_rest,
                          const Points& rest, const std::vector<int32_t>& point_source,
                          const std::vector<int32_t>& cell_source,
                          const std::vector<int32_t>& carried);
  int32_t units() const { return static_cast<int32_t>(first_.size()); }

  // State: laws, offsets, alpha and dissipation, as bytes and back; Parse
  // checks the bytes against this solid's cells, units and entries
  // (DataLoss naming what is wrong) without changing anything.
  struct State {
    std::vector<FlowLaw> laws;
    std::vector<double> offsets, alpha, dissipation;
  };
  std::string SaveState() const;
  State state() const { return {laws_, offsets_, alpha_, dissipation_}; }
  // For a solid of `cells` control cells whose model has `units`.
  static absl::StatusOr<State> ParseState(std::string_view bytes, int32_t cells, Units units);
  void set_state(State s);
  // The stability guard's rollback.
  void Checkpoint();
  void Rollback();

 private:
  void FlowUnit(int32_t unit, const double* u, const double* ku);
  // Units sized (offsets, alpha, dissipation zero) unless they already are.
  void SizeUnits(int64_t entries);
  std::vector<FlowLaw> laws_;           // per control cell
  std::vector<int32_t> unit_cell_;      // unit -> control cell (its law)
  std::array<int32_t, 3> base_{};       // element units: kind k's first unit
  std::vector<double> scale_;           // s_u = E V per unit
  std::vector<int32_t> first_, size_;   // support ranges per unit (the model's)
  int64_t entries_ = 0;
  std::vector<double> offsets_;
  std::vector<double> alpha_, dissipation_;  // per unit
  // Per unit: its law yields or it has flowed (offsets not all zero).
  std::vector<uint8_t> active_;
  void UpdateActive();
  double dt_ = 0;
  State checkpoint_;
};

}  // namespace dynsolid::material
