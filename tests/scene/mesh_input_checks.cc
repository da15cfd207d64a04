#include "tests/scene/mesh_input_checks.h"

#include <algorithm>
#include <map>
#include <numeric>
#include <set>
#include <utility>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"

namespace dynsolid::scene::testing {
namespace {

struct FaceUse {
  int32_t cell;
  int32_t local;
};

int32_t Find(std::vector<int32_t>& parent, int32_t x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

// True when b is a reversed as cyclic sequences.
bool Reversed(const std::vector<int32_t>& a, const std::vector<int32_t>& b) {
  if (a.size() != b.size()) return false;
  const size_t n = a.size();
  const auto it = std::find(b.begin(), b.end(), a[0]);
  if (it == b.end()) return false;
  const size_t s = static_cast<size_t>(it - b.begin());
  for (size_t i = 0; i < n; ++i) {
    if (a[i] != b[(s + n - i) % n]) return false;
  }
  return true;
}

}  // namespace

double CellVolume(const mesh::MeshInput& input, int32_t c) {
  double six_v = 0;
  for (const std::vector<int32_t>& loop : input.cells[c]) {
    const Eigen::Vector3d a = input.vertices.row(loop[0]);
    for (size_t i = 1; i + 1 < loop.size(); ++i) {
      const Eigen::Vector3d b = input.vertices.row(loop[i]);
      const Eigen::Vector3d d = input.vertices.row(loop[i + 1]);
      six_v += a.dot(b.cross(d));
    }
  }
  return six_v / 6.0;
}

absl::Status CheckMeshInput(const mesh::MeshInput& input) {
  const int64_t nv = input.vertices.rows();
  std::vector<uint8_t> used(static_cast<size_t>(nv), 0);
  std::map<std::vector<int32_t>, std::vector<FaceUse>> faces;
  for (int32_t c = 0; c < static_cast<int32_t>(input.cells.size()); ++c) {
    std::set<std::pair<int32_t, int32_t>> directed;
    for (int32_t f = 0; f < static_cast<int32_t>(input.cells[c].size()); ++f) {
      const std::vector<int32_t>& loop = input.cells[c][f];
      if (loop.size() < 3) {
        return absl::InvalidArgumentError(absl::StrCat("cell ", c, " face ", f, " has ",
                                                       loop.size(), " vertices"));
      }
      for (size_t i = 0; i < loop.size(); ++i) {
        if (loop[i] < 0 || loop[i] >= nv) {
          return absl::InvalidArgumentError(
              absl::StrCat("cell ", c, " face ", f, " vertex ", loop[i], " out of range"));
        }
        used[loop[i]] = 1;
        if (!directed.emplace(loop[i], loop[(i + 1) % loop.size()]).second) {
          return absl::InvalidArgumentError(absl::StrCat(
              "cell ", c, ": directed edge ", loop[i], "->", loop[(i + 1) % loop.size()],
              " appears twice (inconsistent orientation)"));
        }
      }
      std::vector<int32_t> key = loop;
      std::sort(key.begin(), key.end());
      if (std::adjacent_find(key.begin(), key.end()) != key.end()) {
        return absl::InvalidArgumentError(
            absl::StrCat("cell ", c, " face ", f, " repeats a vertex"));
      }
      faces[key].push_back({c, f});
    }
    for (const auto& [a, b] : directed) {
      if (!directed.contains({b, a})) {
        return absl::InvalidArgumentError(
            absl::StrCat("cell ", c, " is open at edge ", a, "-", b));
      }
    }
    const double volume = CellVolume(input, c);
    if (!(volume > 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("cell ", c, " has volume ", volume, " (must be > 0: loops outward)"));
    }
  }
  for (int64_t v = 0; v < nv; ++v) {
    if (!used[v]) return absl::InvalidArgumentError(absl::StrCat("vertex ", v, " is unused"));
  }
  for (const auto& [key, uses] : faces) {
    if (uses.size() > 2) {
      return absl::InvalidArgumentError(
          absl::StrCat("a face of cell ", uses[0].cell, " lies in ", uses.size(), " cells"));
    }
    if (uses.size() == 2) {
      const auto& a = input.cells[uses[0].cell][uses[0].local];
      const auto& b = input.cells[uses[1].cell][uses[1].local];
      if (uses[0].cell == uses[1].cell || !Reversed(a, b)) {
        return absl::InvalidArgumentError(absl::StrCat("the face shared by cells ", uses[0].cell,
                                                       " and ", uses[1].cell,
                                                       " does not have opposite loops"));
      }
    }
  }
  return absl::OkStatus();
}

int32_t CountComponents(const mesh::MeshInput& input) {
  const int32_t n = static_cast<int32_t>(input.cells.size());
  std::vector<int32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::map<std::vector<int32_t>, int32_t> first_cell;
  for (int32_t c = 0; c < n; ++c) {
    for (const std::vector<int32_t>& loop : input.cells[c]) {
      std::vector<int32_t> key = loop;
      std::sort(key.begin(), key.end());
      auto [it, inserted] = first_cell.emplace(key, c);
      if (!inserted) parent[Find(parent, c)] = Find(parent, it->second);
    }
  }
  int32_t components = 0;
  for (int32_t c = 0; c < n; ++c) components += Find(parent, c) == c;
  return components;
}

}  // namespace dynsolid::scene::testing
