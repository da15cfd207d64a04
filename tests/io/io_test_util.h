// Helpers shared by the io tests: paths, temp files, running /usr/bin/python3
// and cell geometry from MeshInput loops.
#pragma once

#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "solver/mesh/cell_complex.h"

namespace dynsolid::io::testing {

inline std::string SourceDir() {
  const char* dir = std::getenv("DYNSOLID_SOURCE_DIR");
  return dir != nullptr && *dir != '\0' ? std::string(dir) : std::string(".");
}

inline std::string DataPath(const std::string& name) {
  return SourceDir() + "/tests/io/data/" + name;
}

// A fresh directory under the test temp dir, removed at the end of its
// scope unless the test has failed (then its files are left to look at).
class ScopedTempDir {
 public:
  ScopedTempDir() : path_(::testing::TempDir() + "dynsolid_io_XXXXXX") {
    if (mkdtemp(path_.data()) == nullptr) {
      ADD_FAILURE() << "mkdtemp failed for " << path_;
      path_.clear();
    }
  }
  ScopedTempDir(const ScopedTempDir&) = delete;
  ScopedTempDir& operator=(const ScopedTempDir&) = delete;
  ~ScopedTempDir() {
    if (path_.empty()) return;
    if (::testing::Test::HasFailure()) {
      std::cerr << "test files kept in " << path_ << "\n";
      return;
    }
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

inline void WriteTextFile(const std::string& path, const std::string& contents) {
  std::ofstream out(path, std::ios::binary);
  out << contents;
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

inline std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

// Runs `command` through the shell, capturing stdout and stderr.
inline CommandResult RunCommand(const std::string& command) {
  CommandResult r;
  std::FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return r;
  char buffer[4096];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) r.output.append(buffer, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Runs tests/io/read_vtu.py (meshio, Debian's /usr/bin/python3) on `file`
// with expectation arguments; exit code 0 when all expectations hold.
inline CommandResult RunMeshio(const std::string& file, const std::string& expectations) {
  return RunCommand("/usr/bin/python3 '" + SourceDir() + "/tests/io/read_vtu.py' '" + file + "' " +
                    expectations);
}

// Expects meshio (RunMeshio) to read `file` as `expectations` say.
inline void ExpectMeshioReads(const std::string& file, const std::string& expectations) {
  const CommandResult r = RunMeshio(file, expectations);
  EXPECT_EQ(r.exit_code, 0) << "meshio reading " << file << ":\n" << r.output;
}

// Signed volume of cell `c` from its loops (divergence theorem, each loop
// fanned from its centroid): positive when every loop is outward.
inline double CellVolume(const mesh::MeshInput& in, size_t c) {
  double six_v = 0.0;
  for (const auto& loop : in.cells[c]) {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int32_t v : loop) centre += in.vertices.row(v).transpose();
    centre /= static_cast<double>(loop.size());
    for (size_t i = 0; i < loop.size(); ++i) {
      const Eigen::Vector3d a = in.vertices.row(loop[i]).transpose();
      const Eigen::Vector3d b = in.vertices.row(loop[(i + 1) % loop.size()]).transpose();
      six_v += centre.dot(a.cross(b));
    }
  }
  return six_v / 6.0;
}

// A description of the cells independent of vertex and cell numbering:
// each face as its loop of positions, rotated to start at the smallest
// (orientation kept); each cell as its sorted faces; cells sorted.
using CanonicalFace = std::vector<std::array<double, 3>>;
using CanonicalCell = std::vector<CanonicalFace>;

inline std::vector<CanonicalCell> Canonical(const mesh::MeshInput& in) {
  std::vector<CanonicalCell> cells;
  for (const auto& cell : in.cells) {
    CanonicalCell cc;
    for (const auto& loop : cell) {
      CanonicalFace f;
      for (int32_t v : loop) f.push_back({in.vertices(v, 0), in.vertices(v, 1), in.vertices(v, 2)});
      std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
      cc.push_back(std::move(f));
    }
    std::sort(cc.begin(), cc.end());
    cells.push_back(std::move(cc));
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

}  // namespace dynsolid::io::testing
