// Boundary surfaces for the export tests (STL, binary PLY, glTF), with the
// little-endian readers the tests use to read the files back byte by byte.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <bit>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/mesh/boundary.h"
#include "solver/mesh/cell_complex.h"
#include "solver/subdivision/mcj.h"
#include "tests/testing/meshes.h"

namespace dynsolid::io::testing {

// The boundary of one cube of edge `h` at [0, h]^3 (6 quads, 8 vertices).
inline mesh::BoundarySurface CubeSurface(double h) {
  absl::StatusOr<mesh::CellComplex> cube =
      mesh::CellComplex::FromInput(dynsolid::testing::Grid(1, 1, 1, h));
  EXPECT_TRUE(cube.ok()) << cube.status();
  return cube.ok() ? mesh::ExtractBoundary(*cube) : mesh::BoundarySurface{};
}

// The boundary of a 2x2x2 block of unit cubes subdivided `levels` times
// (curved quads), with its fine complex's total cell volume.
struct SubdividedBlock {
  mesh::BoundarySurface surface;
  double cell_volume = 0.0;
};

inline SubdividedBlock SubdividedBlockSurface(int levels) {
  SubdividedBlock b;
  absl::StatusOr<mesh::CellComplex> block =
      mesh::CellComplex::FromInput(dynsolid::testing::Grid(2, 2, 2));
  EXPECT_TRUE(block.ok()) << block.status();
  if (!block.ok()) return b;
  auto control = std::make_shared<const mesh::CellComplex>(*std::move(block));
  absl::StatusOr<subdivision::Hierarchy> h = subdivision::Subdivide(control, levels, {});
  EXPECT_TRUE(h.ok()) << h.status();
  if (!h.ok()) return b;
  b.surface = mesh::ExtractBoundary(*h->fine);
  for (int32_t c = 0; c < h->fine->num_cells(); ++c) b.cell_volume += h->fine->CellVolume(c);
  return b;
}

// Adds per-vertex fields to `s`: "height" (z, 1 component) and "offset"
// (3 components: the position minus (1, 1, 1)), values that are not exact
// in float32 so that a float/double mix-up shows.
inline void AddFields(mesh::BoundarySurface& s) {
  const int64_t n = s.positions.rows();
  mesh::VertexField height{"height", 1, {}};
  mesh::VertexField offset{"offset", 3, {}};
  for (int64_t i = 0; i < n; ++i) {
    height.values.push_back(s.positions(i, 2) / 3.0 + 0.1);
    for (int k = 0; k < 3; ++k) offset.values.push_back(s.positions(i, k) - 1.0);
  }
  s.fields.push_back(std::move(height));
  s.fields.push_back(std::move(offset));
}

// Enclosed volume of the surface's fan triangles (divergence theorem), in
// double from the stored positions.
inline double FanVolume(const mesh::BoundarySurface& s) {
  double six_v = 0.0;
  for (int32_t f = 0; f < s.faces.rows(); ++f) {
    const auto loop = s.faces.row(f);
    const Eigen::Vector3d a = s.positions.row(loop[0]);
    for (size_t i = 1; i + 1 < loop.size(); ++i) {
      six_v += a.dot(Eigen::Vector3d(s.positions.row(loop[i]))
                         .cross(Eigen::Vector3d(s.positions.row(loop[i + 1]))));
    }
  }
  return six_v / 6.0;
}

inline int64_t FanTriangles(const mesh::BoundarySurface& s) {
  int64_t n = 0;
  for (int32_t f = 0; f < s.faces.rows(); ++f) n += s.faces.row_size(f) - 2;
  return n;
}

// Little-endian readers at byte offset `at` (the caller checks the size).
inline uint32_t U32At(const std::string& b, size_t at) {
  uint32_t v = 0;
  for (int k = 3; k >= 0; --k) v = (v << 8) | static_cast<uint8_t>(b[at + k]);
  return v;
}
inline uint16_t U16At(const std::string& b, size_t at) {
  return static_cast<uint16_t>(static_cast<uint8_t>(b[at]) |
                               (static_cast<uint8_t>(b[at + 1]) << 8));
}
inline float F32At(const std::string& b, size_t at) { return std::bit_cast<float>(U32At(b, at)); }
inline double F64At(const std::string& b, size_t at) {
  const uint64_t lo = U32At(b, at);
  const uint64_t hi = U32At(b, at + 4);
  return std::bit_cast<double>(lo | (hi << 32));
}
inline Eigen::Vector3d Vec3At(const std::string& b, size_t at) {
  return {F32At(b, at), F32At(b, at + 4), F32At(b, at + 8)};
}

}  // namespace dynsolid::io::testing
