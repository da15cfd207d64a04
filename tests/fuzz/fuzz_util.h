// Helpers shared by the libFuzzer targets (tests/fuzz/*_fuzz.cc).
//
// Seeds: each target can write its own seed inputs, made with the real
// encoders (SaveState, FrameRecord, SurfaceEncoder, ...), when run with
// DYNSOLID_FUZZ_WRITE_SEEDS=<dir> (it writes them and exits in
// LLVMFuzzerInitialize). tests/fuzz/corpus/<name>/ holds the committed ones.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace dynsolid::fuzz {

// Stops the run (libFuzzer saves the input) when an invariant fails.
#define FUZZ_CHECK(cond, ...)                                             \
  do {                                                                    \
    if (!(cond)) {                                                        \
      std::fprintf(stderr, "FUZZ_CHECK failed: %s (%s:%d)\n  ", #cond,    \
                   __FILE__, __LINE__);                                   \
      std::fprintf(stderr, __VA_ARGS__);                                  \
      std::fprintf(stderr, "\n");                                         \
      std::abort();                                                       \
    }                                                                     \
  } while (0)

// A file of this process's own (the readers that take a path read it), in
// memory when /dev/shm is there: rewriting a file on ext4 at every run
// waits for the disk (a truncated file is flushed on close) and took the
// journal target from hundreds of runs a second to ten on a busy disk.
inline std::string TempPath(std::string_view suffix) {
  const char* dir = std::getenv("DYNSOLID_FUZZ_TMPDIR");
  if (dir == nullptr || *dir == 0) dir = ::access("/dev/shm", W_OK) == 0 ? "/dev/shm" : nullptr;
  if (dir == nullptr) dir = std::getenv("TMPDIR");
  std::string path = std::string(dir != nullptr && *dir != 0 ? dir : "/tmp") + "/dynsolid_fuzz_" +
                     std::to_string(::getpid()) + std::string(suffix);
  // Removed when the process exits normally (a crash leaves it: the
  // reproducer is libFuzzer's artifact, not this file).
  static std::vector<std::string>* made = [] {
    auto* v = new std::vector<std::string>;
    std::atexit([] {
      for (const std::string& p : *made) ::unlink(p.c_str());
    });
    return v;
  }();
  made->push_back(path);
  return path;
}

// Writes `bytes` to `path` as a new file (unlinking the old one first: no
// truncation, see TempPath).
inline void WriteFile(const std::string& path, std::string_view bytes) {
  ::unlink(path.c_str());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    std::abort();
  }
}

// The seed directory asked for (DYNSOLID_FUZZ_WRITE_SEEDS), or "".
inline std::string SeedDir() {
  const char* dir = std::getenv("DYNSOLID_FUZZ_WRITE_SEEDS");
  return dir != nullptr ? dir : "";
}

// Several messages in one input: each as a 2-byte little-endian length and
// that many bytes (a short last chunk takes what is left).
inline std::vector<std::string_view> SplitChunks(std::string_view in) {
  std::vector<std::string_view> out;
  while (in.size() >= 2) {
    const size_t n = static_cast<unsigned char>(in[0]) |
                     (static_cast<size_t>(static_cast<unsigned char>(in[1])) << 8);
    in.remove_prefix(2);
    const size_t take = n < in.size() ? n : in.size();
    out.push_back(in.substr(0, take));
    in.remove_prefix(take);
  }
  return out;
}

inline std::string JoinChunks(const std::vector<std::string>& chunks) {
  std::string out;
  for (const std::string& c : chunks) {
    if (c.size() > 0xffff) {
      std::fprintf(stderr, "seed chunk of %zu bytes is too long\n", c.size());
      std::abort();
    }
    out.push_back(static_cast<char>(c.size() & 0xff));
    out.push_back(static_cast<char>(c.size() >> 8));
    out += c;
  }
  return out;
}

}  // namespace dynsolid::fuzz
