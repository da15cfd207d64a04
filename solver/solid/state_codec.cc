#include "solver/solid/state_codec.h"

#include <cstring>

namespace dynsolid::solid {
namespace {


// FNV-1a 64 over bytes: the state's checksum.
// (Format version 3; one multiply per byte in a single chain: about 1.3 ms
// for block4's painted 0.9 MB, which every undoable command paid.)
uint64_t ByteChecksum(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  return h;
}

// Version 4's mixer (WordChecksum, saved_state.h).
uint64_t Mix64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ull;
  x ^= x >> 33;
  return x;
}

// The checksum a state of format `version` carries (3 or 4).
uint64_t Checksum(uint32_t version, std::string_view bytes) {
  return version == 3 ? ByteChecksum(bytes) : WordChecksum(bytes);
}

}  // namespace

// Version 5 ends its payload with the material section (the sample arrays
// and each element's array, which change only when the material does)
// and that section's length; the checksum combines the word checksum of
// what comes before the section with the section's own, which the writer
// keeps from one save to the next (Impl::section_*): a painted
// block's state is about a megabyte of samples, which every undoable
// command saved and summed again.
uint64_t CombinedChecksum(uint64_t before, uint64_t section, uint64_t section_bytes) {
  return Mix64(before ^ Mix64(section ^ Mix64(section_bytes)));
}


// Version 4 (saved_state.h): about 30 times faster than version 3's
// single chain, and any change of a byte still changes its chain.
uint64_t WordChecksum(std::string_view bytes) {
  constexpr uint64_t kPrime = 1099511628211ull;
  uint64_t h[4] = {1469598103934665603ull, 0x9e3779b97f4a7c15ull, 0x632be59bd9b4e019ull,
                   0xbf58476d1ce4e5b9ull};
  const size_t n = bytes.size();
  size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    for (int k = 0; k < 4; ++k) {
      uint64_t w;
      std::memcpy(&w, bytes.data() + i + 8 * k, 8);
      h[k] = (h[k] ^ w) * kPrime;
    }
  }
  for (; i < n; ++i) h[i % 4] = (h[i % 4] ^ static_cast<unsigned char>(bytes[i])) * kPrime;
  uint64_t r = n;
  for (uint64_t x : h) r = Mix64(r ^ Mix64(x));
  return r;
}


absl::StatusOr<StateHeader> ReadStateHeader(std::string_view bytes, uint32_t newest) {
  if (bytes.size() < kStateHeaderBytes + 8 || std::memcmp(bytes.data(), kStateMagic, 8) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solid state: not a dynsolid solid state (", bytes.size(),
        " bytes; it must start with \"DSOLIDST\")"));
  }
  StateReader header(bytes.substr(8, kStateHeaderBytes - 8));
  StateHeader out;
  out.version = header.Get<uint32_t>("version");
  out.fingerprint.first = header.Get<uint64_t>("fingerprint");
  out.fingerprint.second = header.Get<uint64_t>("fingerprint");
  const uint64_t payload_size = header.Get<uint64_t>("payload size");
  // Version 3 differs from 4 only in its checksum, 4 from 5 in the place
  // of the material section and the checksum: still read.
  if (out.version != newest && (out.version < 3 || out.version > newest)) {
    return absl::InvalidArgumentError(absl::StrCat("solid state: format version ", out.version,
                                                   "; this build reads versions 3 to ", newest));
  }
  uint64_t stored_sum;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  bool sum_ok = payload_size == bytes.size() - kStateHeaderBytes - 8;
  if (sum_ok && out.version >= 5) {
    uint64_t n = 0;
    sum_ok = payload_size >= 8;
    if (sum_ok) std::memcpy(&n, bytes.data() + bytes.size() - 16, 8);
    sum_ok = sum_ok && n <= payload_size - 8;
    if (sum_ok) {
      out.section_bytes = n;
      out.section_at = bytes.size() - 16 - out.section_bytes;
      sum_ok = CombinedChecksum(WordChecksum(bytes.substr(0, out.section_at)),
                                WordChecksum(bytes.substr(out.section_at, out.section_bytes)),
                                out.section_bytes) == stored_sum;
    }
  } else if (sum_ok) {
    sum_ok = Checksum(out.version, bytes.substr(0, bytes.size() - 8)) == stored_sum;
  }
  if (!sum_ok) {
    return absl::DataLossError(absl::StrCat("solid state: checksum mismatch over ", bytes.size(),
                                            " bytes: the state is corrupt or truncated"));
  }
  out.payload = bytes.substr(kStateHeaderBytes, payload_size);
  return out;
}

bool ResealState(std::string& bytes) {
  if (bytes.size() < kStateHeaderBytes + 8) return false;
  const uint64_t payload = bytes.size() - kStateHeaderBytes - 8;
  std::memcpy(bytes.data() + kStateHeaderBytes - 8, &payload, 8);
  uint32_t version;
  std::memcpy(&version, bytes.data() + 8, 4);
  const std::string_view body(bytes.data(), bytes.size() - 8);
  uint64_t sum;
  if (version == 3 || version == 4) {
    sum = Checksum(version, body);
  } else {
    uint64_t n = 0;
    if (payload >= 8) std::memcpy(&n, bytes.data() + bytes.size() - 16, 8);
    if (payload < 8 || n > payload - 8) return false;
    const size_t at = bytes.size() - 16 - n;
    sum = CombinedChecksum(WordChecksum(body.substr(0, at)), WordChecksum(body.substr(at, n)), n);
  }
  std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
  return true;
}

}  // namespace dynsolid::solid
