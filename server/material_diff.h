// A paint's inverse on the material as it is now (server/history.h): the
// material samples of the elements a paint changed, before and after, and
// putting one side back where the other still shows.
//
// Works on a solid state's material section (solid::SavedState::section,
// format version 5 and later: the sample arrays, 4 doubles a sample, then
// per element block its elements' array indices) and installs the result
// through Solid::RestoreStateAtClock with the CURRENT rest of the state:
// positions, velocities, loads and pins stay; the forces are recomputed and
// the energy ledger re-baselined at the next step, as a paint does.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "dynsolid/journal.pb.h"
#include "solver/solid/saved_state.h"

namespace dynsolid::solid {
class Solid;
}

namespace dynsolid::server {

struct ElementMaterials {
  std::vector<std::vector<double>> arrays;  // 4 doubles a sample
  std::vector<int32_t> element_array;       // per element, over the blocks
  std::vector<int32_t> block_sizes;
  // Per element, its key: a checksum of its kind and its rest nodes'
  // coordinates (ElementKeys), the same for an element a topology edit
  // left alone.
  std::vector<uint64_t> keys;
};

absl::StatusOr<ElementMaterials> ParseMaterialSection(const std::string& section);
// `solid`'s material (its state's section) with the element keys.
absl::StatusOr<ElementMaterials> MaterialsOf(const solid::Solid& solid);
std::string WriteMaterialSection(const ElementMaterials& m);

// Adds to `change` the elements whose samples differ between `before` and
// `after` (the same elements, by key): an element already in `change` keeps
// its first `before` and takes the new `after` (a stroke of dabs is one
// change).
absl::Status AddPaintDiff(const ElementMaterials& before, const ElementMaterials& after,
                          persist::PaintChange* change);

// Undo (or redo): every element of `change` (by key) whose samples now are
// its after (before) samples, bit for bit, takes its before (after)
// samples; elements painted again since, or rebuilt by an edit, keep
// theirs. Returns how many elements it changed.
absl::StatusOr<int32_t> FlipPaint(const persist::PaintChange& change, bool undo,
                                  ElementMaterials* now);

// The bytes of the state `now` with its material section replaced.
std::string StateWithMaterial(const solid::SavedState& now, const std::string& section);

}  // namespace dynsolid::server
