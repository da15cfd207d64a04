#include "server/tokens.h"

#include <cstdint>

#include "absl/strings/str_format.h"

namespace dynsolid::server {

std::string RandomHex::Next(int bits) {
  std::string out;
  for (int i = 0; i < bits; i += 32) {
    const uint32_t word = static_cast<uint32_t>(device_());
    out += absl::StrFormat("%08x", word);
  }
  return out;
}

bool TokensEqual(absl::string_view presented, absl::string_view stored) {
  if (presented.size() != stored.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < stored.size(); ++i) {
    diff |= static_cast<unsigned char>(presented[i] ^ stored[i]);
  }
  return diff == 0;
}

}  // namespace dynsolid::server
