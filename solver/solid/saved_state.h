// A solid's exact state (Solid::SaveState, format version 5) in two parts,
// for a history that keeps many states of one material: the material
// section (the sample arrays and each element's array, a megabyte on a
// painted block), one object shared by every state saved while the
// material is unchanged, and the rest. Solid::JoinState gives the bytes
// SaveState gives. A state without a section is a whole state's bytes (as
// read from a snapshot).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

namespace dynsolid::solid {

struct SavedState {
  std::string head;       // everything before the material section
  uint64_t head_sum = 0;  // its word checksum
  std::shared_ptr<const std::string> section;  // null: head is the whole state
  uint64_t section_sum = 0;
  // The bytes JoinState gives.
  int64_t bytes() const {
    return static_cast<int64_t>(head.size()) +
           (section != nullptr ? static_cast<int64_t>(section->size()) + 16 : 0);
  }
};

}  // namespace dynsolid::solid
