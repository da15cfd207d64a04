// A 128-bit hash (FNV-1a and a multiplicative mix over 64-bit words), for
// content keys (solid/cell_assembly.h, topology transfer) and fingerprints.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string_view>
#include <utility>

namespace dynsolid {

using Key128 = std::pair<uint64_t, uint64_t>;

class Hash128 {
 public:
  void Mix(uint64_t x) {
    h1_ = (h1_ ^ x) * 1099511628211ull;
    h2_ = (h2_ ^ (x + 0x632be59bd9b4e019ull + (h2_ << 6) + (h2_ >> 2))) * 0xff51afd7ed558ccdull;
  }
  void Double(double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, sizeof(bits));
    Mix(bits);
  }
  void Doubles(const double* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) Double(v[i]);
  }
  void Ints(const int32_t* v, size_t n) {
    Mix(n);
    for (size_t i = 0; i < n; ++i) Mix(static_cast<uint32_t>(v[i]));
  }
  void Bytes(std::string_view s) {
    Mix(s.size());
    for (unsigned char c : s) Mix(c);
  }
  void Key(const Key128& k) {
    Mix(k.first);
    Mix(k.second);
  }
  Key128 value() const { return {h1_, h2_}; }

 private:
  uint64_t h1_ = 1469598103934665603ull, h2_ = 0x9e3779b97f4a7c15ull;
};

struct Key128Hash {
  size_t operator()(const Key128& k) const { return static_cast<size_t>(k.first ^ (k.second * 31)); }
};

}  // namespace dynsolid
