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
#include <string_view>

namespace dynsolid::solid {

// The state format's word checksum (version 4 and later): FNV-1a steps
// over 8-byte words in four independent chains (words k, k + 4, ... in
// chain k % 4), each finished with a 64-bit mixer, combined with the
// length. head_sum and section_sum below are this of their bytes; a
// history that rewrites a section (server/material_diff.h) sums it here.
uint64_t WordChecksum(std::string_view bytes);

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
