#include "solver/scene/generators.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include "absl/strings/string_view.h"
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"

namespace dynsolid::scene {
namespace {

using mesh::MeshInput;

// ---------------------------------------------------------------- checks

absl::Status AtLeast(absl::string_view field, int64_t value, int64_t min) {
  if (value >= min) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat(field, " must be >= ", min, ", got ", value));
}

absl::Status Finite(absl::string_view field, double value) {
  if (std::isfinite(value)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(field, " must be finite, got ", value));
}

absl::Status Positive(absl::string_view field, double value) {
  RETURN_IF_ERROR(Finite(field, value));
  if (value > 0) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(field, " must be > 0, got ", value));
}

// A field where 0 means a default: it must be finite and not negative.
absl::Status PositiveOrDefault(absl::string_view field, double value, absl::string_view dflt) {
  RETURN_IF_ERROR(Finite(field, value));
  if (value >= 0) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat(field, " must be > 0 (0 means ", dflt, "), got ", value));
}

absl::Status FiniteVec(absl::string_view field, const Vec3& v) {
  RETURN_IF_ERROR(Finite(absl::StrCat(field, ".x"), v.x()));
  RETURN_IF_ERROR(Finite(absl::StrCat(field, ".y"), v.y()));
  return Finite(absl::StrCat(field, ".z"), v.z());
}

// Checks that a product of cell counts stays within kMaxGeneratedCells.
// Counts are already >= 1, so the double product is exact well past the cap.
absl::Status CellCap(absl::string_view what, absl::string_view formula, double cells) {
  if (cells <= static_cast<double>(kMaxGeneratedCells)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      what, " would have ", absl::SixDigits(cells), " cells (", formula,
      "), more than the limit of ", kMaxGeneratedCells));
}

// ------------------------------------------------------------- building

// The six outward quads of a hexahedron whose corners are given as
// corner[a + 2b + 4c] for (a, b, c) in {0, 1}^3 along a right-handed
// parametrization (u, v, w) (positive Jacobian). Neighbouring cells of a
// structured grid then see shared faces with opposite loops.
void AddHex(const std::array<int32_t, 8>& c, MeshInput& out) {
  static constexpr int kLoops[6][4] = {
      {0, 4, 6, 2},  // -u
      {1, 3, 7, 5},  // +u
      {0, 1, 5, 4},  // -v
      {2, 6, 7, 3},  // +v
      {0, 2, 3, 1},  // -w
      {4, 5, 7, 6},  // +w
  };
  std::vector<std::vector<int32_t>> faces(6);
  for (int f = 0; f < 6; ++f) {
    faces[f] = {c[kLoops[f][0]], c[kLoops[f][1]], c[kLoops[f][2]], c[kLoops[f][3]]};
  }
  out.cells.push_back(std::move(faces));
}

// Adds lattice cell (a, b, c) of a structured vertex lattice whose
// coordinates (a, b, c) are right-handed; `vertex(a, b, c)` gives the index
// of lattice point (a, b, c). With `periodic_v` the lattice has nv vertex
// columns in b and the last cell wraps to column 0.
template <typename VertexIndex>
void AddLatticeCell(int32_t a, int32_t b, int32_t c, int32_t nv, bool periodic_v,
                    const VertexIndex& vertex, MeshInput& out) {
  const int32_t b1 = periodic_v ? (b + 1) % nv : b + 1;
  const std::array<int32_t, 8> corners = {
      vertex(a, b, c),      vertex(a + 1, b, c),      vertex(a, b1, c),
      vertex(a + 1, b1, c), vertex(a, b, c + 1),      vertex(a + 1, b, c + 1),
      vertex(a, b1, c + 1), vertex(a + 1, b1, c + 1)};
  AddHex(corners, out);
}

}  // namespace

// ================================================================= block

absl::Status ValidateBlock(const BlockGenerator& block) {
  RETURN_IF_ERROR(AtLeast("block.nx", block.nx(), 1));
  RETURN_IF_ERROR(AtLeast("block.ny", block.ny(), 1));
  RETURN_IF_ERROR(AtLeast("block.nz", block.nz(), 1));
  RETURN_IF_ERROR(CellCap("block", "nx * ny * nz",
                          double{1} * block.nx() * block.ny() * block.nz()));
  const Vec3& s = block.size();
  if (s.x() != 0 || s.y() != 0 || s.z() != 0) {
    static constexpr absl::string_view kHint =
        " (or leave all of block.size at 0 for unit cells)";
    const double comps[3] = {s.x(), s.y(), s.z()};
    const char* names[3] = {"block.size.x", "block.size.y", "block.size.z"};
    for (int k = 0; k < 3; ++k) {
      RETURN_IF_ERROR(Finite(names[k], comps[k]));
      if (!(comps[k] > 0)) {
        return absl::InvalidArgumentError(
            absl::StrCat(names[k], " must be > 0", kHint, ", got ", comps[k]));
      }
    }
  }
  return FiniteVec("block.origin", block.origin());
}

absl::StatusOr<MeshInput> GenerateBlock(const BlockGenerator& block) {
  RETURN_IF_ERROR(ValidateBlock(block));
  const int32_t nx = block.nx(), ny = block.ny(), nz = block.nz();
  const bool unit = block.size().x() == 0 && block.size().y() == 0 && block.size().z() == 0;
  const Eigen::Vector3d size = unit ? Eigen::Vector3d(nx, ny, nz)
                                    : Eigen::Vector3d(block.size().x(), block.size().y(),
                                                      block.size().z());
  const Eigen::Vector3d origin(block.origin().x(), block.origin().y(), block.origin().z());

  MeshInput out;
  out.origin = absl::StrCat("block ", nx, "x", ny, "x", nz);
  out.vertices.resize(int64_t{nx + 1} * (ny + 1) * (nz + 1), 3);
  for (int32_t k = 0; k <= nz; ++k) {
    for (int32_t j = 0; j <= ny; ++j) {
      for (int32_t i = 0; i <= nx; ++i) {
        const int64_t v = i + int64_t{nx + 1} * (j + int64_t{ny + 1} * k);
        // i * size / n rather than i * (size / n): the far face lands exactly.
        out.vertices.row(v) = origin + Eigen::Vector3d(i * size.x() / nx, j * size.y() / ny,
                                                       k * size.z() / nz);
      }
    }
  }
  auto vertex = [&](int32_t i, int32_t j, int32_t k) {
    return static_cast<int32_t>(i + (nx + 1) * (j + (ny + 1) * k));
  };
  out.cells.reserve(static_cast<size_t>(nx) * ny * nz);
  for (int32_t k = 0; k < nz; ++k) {
    for (int32_t j = 0; j < ny; ++j) {
      for (int32_t i = 0; i < nx; ++i) AddLatticeCell(i, j, k, ny, false, vertex, out);
    }
  }
  return out;
}

// ================================================================== beam

absl::Status ValidateBeam(const BeamGenerator& beam) {
  RETURN_IF_ERROR(Positive("beam.length", beam.length()));
  RETURN_IF_ERROR(Positive("beam.width", beam.width()));
  RETURN_IF_ERROR(Positive("beam.height", beam.height()));
  RETURN_IF_ERROR(AtLeast("beam.cells_along", beam.cells_along(), 1));
  RETURN_IF_ERROR(AtLeast("beam.cells_across", beam.cells_across(), 1));
  return CellCap("beam", "cells_along * cells_across^2",
                 double{1} * beam.cells_along() * beam.cells_across() * beam.cells_across());
}

absl::StatusOr<MeshInput> GenerateBeam(const BeamGenerator& beam) {
  RETURN_IF_ERROR(ValidateBeam(beam));
  BlockGenerator block;
  block.set_nx(beam.cells_along());
  block.set_ny(beam.cells_across());
  block.set_nz(beam.cells_across());
  block.mutable_size()->set_x(beam.length());
  block.mutable_size()->set_y(beam.width());
  block.mutable_size()->set_z(beam.height());
  block.mutable_origin()->set_x(0);
  block.mutable_origin()->set_y(-0.5 * beam.width());
  block.mutable_origin()->set_z(-0.5 * beam.height());
  ASSIGN_OR_RETURN(MeshInput out, GenerateBlock(block));
  out.origin = absl::StrCat("beam ", beam.length(), " x ", beam.width(), " x ", beam.height(),
                            " m, ", beam.cells_along(), "x", beam.cells_across(), "x",
                            beam.cells_across(), " cells");
  return out;
}

// ================================================================== tube

absl::Status ValidateTube(const TubeGenerator& tube) {
  RETURN_IF_ERROR(AtLeast("tube.segments", tube.segments(), 3));
  RETURN_IF_ERROR(AtLeast("tube.layers", tube.layers(), 1));
  RETURN_IF_ERROR(AtLeast("tube.slices", tube.slices(), 1));
  RETURN_IF_ERROR(CellCap("tube", "segments * layers * slices",
                          double{1} * tube.segments() * tube.layers() * tube.slices()));
  RETURN_IF_ERROR(Positive("tube.inner_radius", tube.inner_radius()));
  RETURN_IF_ERROR(Positive("tube.outer_radius", tube.outer_radius()));
  if (!(tube.inner_radius() < tube.outer_radius())) {
    return absl::InvalidArgumentError(
        absl::StrCat("tube.inner_radius (", tube.inner_radius(),
                     ") must be less than tube.outer_radius (", tube.outer_radius(), ")"));
  }
  RETURN_IF_ERROR(Positive("tube.length", tube.length()));
  return PositiveOrDefault("tube.end_scale", tube.end_scale(), "1, a straight tube");
}

absl::StatusOr<MeshInput> GenerateTube(const TubeGenerator& tube) {
  RETURN_IF_ERROR(ValidateTube(tube));
  const int32_t ns = tube.segments(), nl = tube.layers(), nk = tube.slices();
  const double end_scale = tube.end_scale() == 0 ? 1.0 : tube.end_scale();
  const double r0 = tube.inner_radius(), r1 = tube.outer_radius();

  MeshInput out;
  out.origin = absl::StrCat("tube ", ns, "x", nl, "x", nk);
  out.vertices.resize(int64_t{nl + 1} * ns * (nk + 1), 3);
  for (int32_t k = 0; k <= nk; ++k) {
    const double t = static_cast<double>(k) / nk;
    const double z = k * tube.length() / nk;
    const double scale = 1.0 + (end_scale - 1.0) * t;
    for (int32_t s = 0; s < ns; ++s) {
      const double angle = 2.0 * std::numbers::pi * s / ns;
      const double c = std::cos(angle), sn = std::sin(angle);
      for (int32_t l = 0; l <= nl; ++l) {
        const double r = scale * (r0 + (r1 - r0) * l / nl);
        const int64_t v = l + int64_t{nl + 1} * (s + int64_t{ns} * k);
        out.vertices.row(v) = Eigen::Vector3d(r * c, r * sn, z);
      }
    }
  }
  // Parametrization (radial, angular, axial) is right-handed.
  auto vertex = [&](int32_t l, int32_t s, int32_t k) {
    return static_cast<int32_t>(l + (nl + 1) * (s + ns * k));
  };
  out.cells.reserve(static_cast<size_t>(ns) * nl * nk);
  for (int32_t k = 0; k < nk; ++k) {
    for (int32_t s = 0; s < ns; ++s) {
      for (int32_t l = 0; l < nl; ++l) AddLatticeCell(l, s, k, ns, true, vertex, out);
    }
  }
  return out;
}

// ================================================================= torus

absl::Status ValidateTorus(const TorusGenerator& torus) {
  RETURN_IF_ERROR(AtLeast("torus.segments", torus.segments(), 3));
  RETURN_IF_ERROR(AtLeast("torus.cross", torus.cross(), 1));
  RETURN_IF_ERROR(CellCap("torus", "segments * cross^2",
                          double{1} * torus.segments() * torus.cross() * torus.cross()));
  RETURN_IF_ERROR(Positive("torus.major_radius", torus.major_radius()));
  RETURN_IF_ERROR(Positive("torus.tube_half_width", torus.tube_half_width()));
  if (!(torus.tube_half_width() < torus.major_radius())) {
    return absl::InvalidArgumentError(absl::StrCat(
        "torus.tube_half_width (", torus.tube_half_width(),
        ") must be less than torus.major_radius (", torus.major_radius(),
        "), or the torus would reach the axis"));
  }
  return absl::OkStatus();
}

absl::StatusOr<MeshInput> GenerateTorus(const TorusGenerator& torus) {
  RETURN_IF_ERROR(ValidateTorus(torus));
  const int32_t ns = torus.segments(), nc = torus.cross();
  const double major = torus.major_radius(), half = torus.tube_half_width();

  MeshInput out;
  out.origin = absl::StrCat("torus ", ns, "x", nc, "x", nc);
  out.vertices.resize(int64_t{ns} * (nc + 1) * (nc + 1), 3);
  for (int32_t s = 0; s < ns; ++s) {
    const double angle = 2.0 * std::numbers::pi * s / ns;
    const double c = std::cos(angle), sn = std::sin(angle);
    for (int32_t j = 0; j <= nc; ++j) {
      const double z = half * (2.0 * j / nc - 1.0);
      for (int32_t i = 0; i <= nc; ++i) {
        const double r = major + half * (2.0 * i / nc - 1.0);
        const int64_t v = i + int64_t{nc + 1} * (j + int64_t{nc + 1} * s);
        out.vertices.row(v) = Eigen::Vector3d(r * c, r * sn, z);
      }
    }
  }
  // Lattice coordinates (i radial, s angular, j axial): right-handed.
  auto vertex = [&](int32_t i, int32_t s, int32_t j) {
    return static_cast<int32_t>(i + (nc + 1) * (j + (nc + 1) * s));
  };
  out.cells.reserve(static_cast<size_t>(ns) * nc * nc);
  for (int32_t s = 0; s < ns; ++s) {
    for (int32_t j = 0; j < nc; ++j) {
      for (int32_t i = 0; i < nc; ++i) AddLatticeCell(i, s, j, ns, true, vertex, out);
    }
  }
  return out;
}

// ================================================================ voxels

namespace {

struct VoxelBounds {
  std::array<int64_t, 3> lo{0, 0, 0};  // inclusive
  std::array<int64_t, 3> hi{0, 0, 0};  // exclusive
  int64_t extent(int k) const { return hi[k] - lo[k]; }
  double volume() const { return double{1} * extent(0) * extent(1) * extent(2); }
};

// Bounding box of the added boxes; valid only after ValidateVoxels.
VoxelBounds AddedBounds(const VoxelGenerator& voxels) {
  VoxelBounds b;
  bool first = true;
  for (const VoxelBox& box : voxels.boxes()) {
    if (box.subtract()) continue;
    const std::array<int64_t, 3> lo = {box.x0(), box.y0(), box.z0()};
    const std::array<int64_t, 3> hi = {box.x1(), box.y1(), box.z1()};
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = first ? lo[k] : std::min(b.lo[k], lo[k]);
      b.hi[k] = first ? hi[k] : std::max(b.hi[k], hi[k]);
    }
    first = false;
  }
  return b;
}

// manifold[mask]: the 8 voxels around a grid vertex, bit dx + 2 dy + 4 dz
// set when voxel (vx - 1 + dx, vy - 1 + dy, vz - 1 + dz) is filled. The
// boundary surface is a manifold at the vertex (the set is "well composed")
// exactly when the filled voxels and the empty voxels of that 2x2x2 block
// are each connected through shared faces, i.e. through index bits.
std::array<bool, 256> ManifoldVertexTable() {
  std::array<bool, 256> table{};
  auto connected = [](unsigned set) {
    if (set == 0) return true;
    unsigned reached = set & (~set + 1);  // lowest member
    for (bool grew = true; grew;) {
      grew = false;
      for (unsigned b = 0; b < 8; ++b) {
        if (!(reached >> b & 1)) continue;
        for (unsigned axis : {1u, 2u, 4u}) {
          const unsigned n = b ^ axis;
          if ((set >> n & 1) && !(reached >> n & 1)) {
            reached |= 1u << n;
            grew = true;
          }
        }
      }
    }
    return reached == set;
  };
  for (unsigned mask = 0; mask < 256; ++mask) {
    table[mask] = connected(mask) && connected(~mask & 0xffu);
  }
  return table;
}

}  // namespace

absl::Status ValidateVoxels(const VoxelGenerator& voxels) {
  if (voxels.boxes().empty()) {
    return absl::InvalidArgumentError("voxels.boxes is empty: add at least one box");
  }
  bool any_added = false;
  for (int b = 0; b < voxels.boxes_size(); ++b) {
    const VoxelBox& box = voxels.boxes(b);
    const std::string name = absl::StrCat("voxels.boxes[", b, "]");
    const int32_t lo[3] = {box.x0(), box.y0(), box.z0()};
    const int32_t hi[3] = {box.x1(), box.y1(), box.z1()};
    static constexpr const char* kAxis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      if (hi[k] <= lo[k]) {
        return absl::InvalidArgumentError(absl::StrCat(
            name, ".", kAxis[k], "1 (", hi[k], ") must be greater than ", name, ".", kAxis[k],
            "0 (", lo[k], "): boxes are half-open [", kAxis[k], "0, ", kAxis[k], "1)"));
      }
    }
    any_added |= !box.subtract();
  }
  if (!any_added) {
    return absl::InvalidArgumentError(
        "voxels.boxes adds nothing: every box has subtract: true");
  }
  RETURN_IF_ERROR(PositiveOrDefault("voxels.cell_size", voxels.cell_size(), "1"));
  const VoxelBounds bounds = AddedBounds(voxels);
  if (bounds.volume() > static_cast<double>(kMaxVoxelGrid)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "voxels: the bounding box of the added boxes holds ", absl::SixDigits(bounds.volume()),
        " voxels (", bounds.extent(0), " x ", bounds.extent(1), " x ", bounds.extent(2),
        "), more than the limit of ", kMaxVoxelGrid));
  }
  double work = 0;
  for (const VoxelBox& box : voxels.boxes()) {
    const std::array<int64_t, 3> lo = {box.x0(), box.y0(), box.z0()};
    const std::array<int64_t, 3> hi = {box.x1(), box.y1(), box.z1()};
    double volume = 1;
    for (int k = 0; k < 3; ++k) {
      volume *= static_cast<double>(
          std::max<int64_t>(0, std::min(hi[k], bounds.hi[k]) - std::max(lo[k], bounds.lo[k])));
    }
    work += volume;
  }
  if (work > static_cast<double>(kMaxVoxelWork)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "voxels: the boxes cover ", absl::SixDigits(work),
        " voxels in all (counting overlaps), more than the limit of ", kMaxVoxelWork));
  }
  return absl::OkStatus();
}

absl::StatusOr<MeshInput> GenerateVoxels(const VoxelGenerator& voxels) {
  RETURN_IF_ERROR(ValidateVoxels(voxels));
  const VoxelBounds bounds = AddedBounds(voxels);
  const int64_t ex = bounds.extent(0), ey = bounds.extent(1), ez = bounds.extent(2);
  std::vector<uint8_t> filled(static_cast<size_t>(ex * ey * ez), 0);
  auto index = [&](int64_t x, int64_t y, int64_t z) {
    return static_cast<size_t>((x - bounds.lo[0]) + ex * ((y - bounds.lo[1]) + ey * (z - bounds.lo[2])));
  };
  for (const VoxelBox& box : voxels.boxes()) {
    // Subtracted boxes may reach outside the added ones: clip.
    const int64_t x0 = std::max<int64_t>(box.x0(), bounds.lo[0]);
    const int64_t y0 = std::max<int64_t>(box.y0(), bounds.lo[1]);
    const int64_t z0 = std::max<int64_t>(box.z0(), bounds.lo[2]);
    const int64_t x1 = std::min<int64_t>(box.x1(), bounds.hi[0]);
    const int64_t y1 = std::min<int64_t>(box.y1(), bounds.hi[1]);
    const int64_t z1 = std::min<int64_t>(box.z1(), bounds.hi[2]);
    const uint8_t value = box.subtract() ? 0 : 1;
    for (int64_t z = z0; z < z1; ++z) {
      for (int64_t y = y0; y < y1; ++y) {
        for (int64_t x = x0; x < x1; ++x) filled[index(x, y, z)] = value;
      }
    }
  }
  auto is_filled = [&](int64_t x, int64_t y, int64_t z) {
    if (x < bounds.lo[0] || y < bounds.lo[1] || z < bounds.lo[2] || x >= bounds.hi[0] ||
        y >= bounds.hi[1] || z >= bounds.hi[2]) {
      return false;
    }
    return filled[index(x, y, z)] != 0;
  };

  int64_t num_cells = 0;
  for (uint8_t f : filled) num_cells += f;
  if (num_cells == 0) {
    return absl::InvalidArgumentError(
        "voxels: no voxel remains after the subtracted boxes; the solid is empty");
  }
  RETURN_IF_ERROR(CellCap("voxels", "filled voxels", static_cast<double>(num_cells)));

  const std::array<bool, 256> manifold = ManifoldVertexTable();
  const double cell_size = voxels.cell_size() == 0 ? 1.0 : voxels.cell_size();
  // Grid vertex (x, y, z) -> mesh vertex, created on first use.
  const int64_t vx = ex + 1, vy = ey + 1;
  absl::flat_hash_map<int64_t, int32_t> vertex_id;
  std::vector<std::array<int64_t, 3>> grid_vertices;
  absl::Status status;
  auto vertex = [&](int64_t x, int64_t y, int64_t z) -> int32_t {
    const int64_t key = (x - bounds.lo[0]) + vx * ((y - bounds.lo[1]) + vy * (z - bounds.lo[2]));
    auto [it, inserted] = vertex_id.try_emplace(key, static_cast<int32_t>(grid_vertices.size()));
    if (inserted) {
      grid_vertices.push_back({x, y, z});
      unsigned mask = 0;
      for (unsigned b = 0; b < 8; ++b) {
        if (is_filled(x - 1 + (b & 1), y - 1 + (b >> 1 & 1), z - 1 + (b >> 2 & 1))) {
          mask |= 1u << b;
        }
      }
      if (!manifold[mask] && status.ok()) {
        status = absl::InvalidArgumentError(absl::StrCat(
            "voxels: the solid is not a manifold at grid vertex (", x, ", ", y, ", ", z,
            "): voxels there touch only along an edge or at a corner; fill or remove one"));
      }
    }
    return it->second;
  };

  MeshInput out;
  out.origin = absl::StrCat("voxels (", num_cells, " cells)");
  out.cells.reserve(static_cast<size_t>(num_cells));
  for (int64_t z = bounds.lo[2]; z < bounds.hi[2]; ++z) {
    for (int64_t y = bounds.lo[1]; y < bounds.hi[1]; ++y) {
      for (int64_t x = bounds.lo[0]; x < bounds.hi[0]; ++x) {
        if (!filled[index(x, y, z)]) continue;
        std::array<int32_t, 8> corners;
        for (int b = 0; b < 8; ++b) {
          corners[b] = vertex(x + (b & 1), y + (b >> 1 & 1), z + (b >> 2 & 1));
        }
        RETURN_IF_ERROR(status);
        AddHex(corners, out);
      }
    }
  }
  out.vertices.resize(static_cast<Eigen::Index>(grid_vertices.size()), 3);
  for (size_t v = 0; v < grid_vertices.size(); ++v) {
    const auto& g = grid_vertices[v];
    out.vertices.row(static_cast<Eigen::Index>(v)) =
        cell_size * Eigen::Vector3d(static_cast<double>(g[0]), static_cast<double>(g[1]),
                                    static_cast<double>(g[2]));
  }
  return out;
}

}  // namespace dynsolid::scene
