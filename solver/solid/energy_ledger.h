// The stability guard's energy account (docs/model.md, the stability
// guard): H = kinetic + strain + penalty-spring energy - the work of the
// external forces never grows in a stable run (damping only lowers it). A
// part of Solid with its own state (docs/architecture.md "The solid's
// parts"): the step hands it the work done and the mechanical energy after
// each sub-step; it says when H grew.
#pragma once

#include <algorithm>
#include <cmath>

#include "absl/status/status.h"

namespace dynsolid::solid {

class EnergyLedger {
 public:
  // What a saved state holds of it.
  struct Values {
    double work = 0;   // J, cumulative external work
    double h_min = 0;  // the lowest H so far
    double peak = 0;   // the highest kinetic + strain + spring energy so far
    bool started = false;
    bool rebase = false;  // re-baseline at the start of the next step
  };

  const Values& values() const { return v_; }
  void set_values(const Values& v) { v_ = v; }

  // A fresh account at mechanical energy `mech` (a new solid, a solid set
  // at rest).
  void Start(double mech) {
    v_ = Values();
    v_.started = true;
    v_.h_min = mech;
    v_.peak = mech;
  }
  // Asks for a new baseline at the next step (after a fix, unfix, paint or
  // edit changed what the energies mean).
  void RequestRebase() { v_.rebase = true; }
  bool rebase_requested() const { return v_.rebase; }
  // The new baseline: no work done, H = mech; the peak kept.
  void Rebase(double mech) {
    v_.work = 0;
    v_.h_min = mech;
    v_.peak = std::max(v_.peak, mech);
    v_.started = true;
    v_.rebase = false;
  }
  void AddWork(double w) { v_.work += w; }
  // The account after sub-step k, whose mechanical energy is `mech`:
  // Internal when H is not finite or rose by more than half the peak.
  absl::Status Close(double mech, int k);

 private:
  Values v_;
};

}  // namespace dynsolid::solid
