// Session ids and tokens: random hex strings from std::random_device, which
// libstdc++ on Linux backs with a non-deterministic source (the CPU's
// RDSEED/RDRAND or the kernel's getrandom), never a seeded PRNG.
#pragma once

#include <random>
#include <string>

#include "absl/strings/string_view.h"

namespace dynsolid::server {

inline constexpr int kTokenBits = 128;     // 32 hex digits
inline constexpr int kSessionIdBits = 64;  // 16 hex digits

// Random bits as lowercase hex. Not thread-safe: one generator per owner
// (the session registry keeps one under its lock).
class RandomHex {
 public:
  RandomHex() = default;
  RandomHex(const RandomHex&) = delete;
  RandomHex& operator=(const RandomHex&) = delete;

  // `bits` random bits (a multiple of 32) as bits / 4 hex digits.
  std::string Next(int bits);

 private:
  std::random_device device_;
};

// Compares a presented token with the stored one in time that depends only
// on their lengths, so timing does not reveal a matching prefix.
bool TokensEqual(absl::string_view presented, absl::string_view stored);

}  // namespace dynsolid::server
