// The solid state's codec (Solid::SaveState, format version 6): the
// binary encoding's writer and reader, the checksums, and the header every
// state starts with. Plain functions over bytes; what the values mean to a
// solid is solid_state.cc's. Private to solver/solid (and its tests and fuzzers).
//
// Layout: "DSOLIDST", the format version (uint32), the solid's fingerprint
// (2 x uint64), the payload's size (uint64), the payload, and a checksum
// (uint64). From version 5 the payload ends with the material section and
// its length, and the checksum combines the section's with the rest's
// (CombinedChecksum).
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "solver/mesh/points.h"
#include "solver/solid/saved_state.h"

namespace dynsolid::solid {

inline constexpr char kStateMagic[8] = {'D', 'S', 'O', 'L', 'I', 'D', 'S', 'T'};
// magic, version, fingerprint, payload size
inline constexpr size_t kStateHeaderBytes = 8 + 4 + 8 + 8 + 8;

// Version 5 and later: the checksum of the bytes before the material
// section (`before`), the section's (`section`) and its length.
uint64_t CombinedChecksum(uint64_t before, uint64_t section, uint64_t section_bytes);

// A state's header, checked: its magic, a version this build reads
// (`newest` and the older ones it still reads: 3 and later), and its
// checksum over the whole state.
struct StateHeader {
  uint32_t version = 0;
  std::pair<uint64_t, uint64_t> fingerprint;
  std::string_view payload;  // the bytes after the header, before the checksum
  // Version 5 and later: where the material section starts in the state's
  // bytes and its length.
  size_t section_at = 0, section_bytes = 0;
};
// InvalidArgument for what is not a state or a version this build does not
// read, DataLoss for a checksum that does not match.
absl::StatusOr<StateHeader> ReadStateHeader(std::string_view bytes, uint32_t newest);

// Rewrites a state's payload size and checksum to match the bytes it
// holds (versions 3 and 4: their checksum over everything before it; any
// other version: the combined checksum over the material section whose
// length the payload's last 8 bytes give), for tests and fuzzers that edit
// a state's bytes and want to reach past the header check. Does nothing to
// bytes too short to hold a header and a checksum; false when it could not
// make a checksum (those, or a section length that does not fit: the
// payload size is rewritten then but not the checksum).
bool ResealState(std::string& bytes);

// Binary state encoding: fixed-width little-endian values (this build runs
// on little-endian machines only), length-prefixed arrays.
class StateWriter {
 public:
  template <typename T>
  void Put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void Doubles(const double* v, size_t n) {
    Put<uint64_t>(n);
    out.append(reinterpret_cast<const char*>(v), n * sizeof(double));
  }
  void Matrix(const Points& m) {
    Put<int64_t>(m.rows());
    out.append(reinterpret_cast<const char*>(m.data()), m.size() * sizeof(double));
  }
  void Bytes(std::string_view s) {
    Put<uint64_t>(s.size());
    out.append(s.data(), s.size());
  }
  void Vec(const Eigen::Vector3d& v) { Doubles(v.data(), 3); }
  std::string out;
};

// Reads what StateWriter wrote; the first failure is kept (DataLoss naming
// what was being read and where) and later reads return zeros.
class StateReader {
 public:
  explicit StateReader(std::string_view bytes) : b_(bytes) {}
  template <typename T>
  T Get(const char* what) {
    T v{};
    if (Need(sizeof(T), what)) {
      std::memcpy(&v, b_.data() + pos_, sizeof(T));
      pos_ += sizeof(T);
    }
    return v;
  }
  // A count that must be at most `max` (guards allocations).
  int64_t Count(const char* what, int64_t max) {
    const uint64_t n = Get<uint64_t>(what);
    if (ok() && n > static_cast<uint64_t>(max)) {
      Fail(absl::StrCat(what, ": count ", n, " is above the possible ", max));
      return 0;
    }
    return static_cast<int64_t>(n);
  }
  std::vector<double> Doubles(const char* what, int64_t expected = -1) {
    const int64_t n = Count(what, static_cast<int64_t>((b_.size() - pos_) / sizeof(double)));
    if (expected >= 0 && ok() && n != expected) {
      Fail(absl::StrCat(what, ": ", n, " values, expected ", expected));
    }
    std::vector<double> v(ok() ? n : 0);
    if (ok() && !v.empty() && Need(v.size() * sizeof(double), what)) {
      std::memcpy(v.data(), b_.data() + pos_, v.size() * sizeof(double));
      pos_ += v.size() * sizeof(double);
    }
    return v;
  }
  Eigen::Vector3d Vec(const char* what) {
    const std::vector<double> v = Doubles(what, 3);
    return ok() ? Eigen::Vector3d(v[0], v[1], v[2]) : Eigen::Vector3d::Zero();
  }
  Points Matrix(const char* what, int64_t rows) {
    const int64_t n = Get<int64_t>(what);
    Points m;
    if (!ok()) return m;
    if (n != rows) {
      Fail(absl::StrCat(what, ": ", n, " rows, the solid has ", rows));
      return m;
    }
    m.resize(rows, 3);
    if (Need(m.size() * sizeof(double), what)) {
      std::memcpy(m.data(), b_.data() + pos_, m.size() * sizeof(double));
      pos_ += m.size() * sizeof(double);
    }
    return m;
  }
  std::string Bytes(const char* what) {
    const int64_t n = Count(what, static_cast<int64_t>(b_.size() - pos_));
    std::string s;
    if (ok() && Need(n, what)) {
      s.assign(b_.data() + pos_, n);
      pos_ += n;
    }
    return s;
  }
  void Fail(std::string message) {
    if (error_.empty()) error_ = std::move(message);
  }
  bool ok() const { return error_.empty(); }
  bool at_end() const { return pos_ == b_.size(); }
  size_t pos() const { return pos_; }
  absl::Status status() const {
    if (ok()) return absl::OkStatus();
    return absl::DataLossError(absl::StrCat("solid state: ", error_));
  }

 private:
  bool Need(size_t n, const char* what) {
    if (!ok()) return false;
    if (b_.size() - pos_ < n) {
      Fail(absl::StrCat("truncated at byte ", pos_, " while reading ", what, " (", n,
                        " bytes needed, ", b_.size() - pos_, " left)"));
      return false;
    }
    return true;
  }
  std::string_view b_;
  size_t pos_ = 0;
  std::string error_;
};


}  // namespace dynsolid::solid
