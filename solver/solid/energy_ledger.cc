#include "solver/solid/energy_ledger.h"

#include "absl/strings/str_cat.h"

namespace dynsolid::solid {

absl::Status EnergyLedger::Close(double mech, int k) {
  const double hamiltonian = mech - v_.work;
  v_.peak = std::max(v_.peak, mech);
  if (!std::isfinite(hamiltonian) ||
      hamiltonian - v_.h_min > 0.5 * v_.peak + 1e-12 * (1.0 + v_.peak)) {
    return absl::InternalError(absl::StrCat(
        "energy grew without external work at sub-step ", k, " (H rose by ",
        hamiltonian - v_.h_min, " J over a peak of ", v_.peak, " J)"));
  }
  v_.h_min = std::min(v_.h_min, hamiltonian);
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
