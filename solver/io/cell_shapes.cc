#include "solver/io/cell_shapes.h"

#include <Eigen/Geometry>

namespace dynsolid::io::internal {
namespace {

// Outward faces in local node numbers (-1 ends a triangle).
constexpr int kTetFaces[4][4] = {{0, 2, 1, -1}, {0, 1, 3, -1}, {1, 2, 3, -1}, {0, 3, 2, -1}};
constexpr int kHexFaces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                 {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
constexpr int kPrismFaces[5][4] = {
    {0, 2, 1, -1}, {3, 4, 5, -1}, {0, 1, 4, 3}, {1, 2, 5, 4}, {2, 0, 3, 5}};
constexpr int kPyramidFaces[5][4] = {
    {0, 3, 2, 1}, {0, 1, 4, -1}, {1, 2, 4, -1}, {2, 3, 4, -1}, {3, 0, 4, -1}};

template <size_t N>
std::vector<std::vector<int32_t>> Faces(const int (&table)[N][4], std::span<const int32_t> nodes) {
  std::vector<std::vector<int32_t>> faces(N);
  for (size_t f = 0; f < N; ++f) {
    const int n = table[f][3] < 0 ? 3 : 4;
    faces[f].resize(n);
    for (int i = 0; i < n; ++i) faces[f][i] = nodes[table[f][i]];
  }
  return faces;
}

}  // namespace

const char* ShapeName(Shape s) {
  switch (s) {
    case Shape::kTetrahedron:
      return "tetrahedron";
    case Shape::kHexahedron:
      return "hexahedron";
    case Shape::kPrism:
      return "prism";
    case Shape::kPyramid:
      return "pyramid";
  }
  return "?";
}

std::vector<std::vector<int32_t>> CellFaces(Shape shape, std::span<const int32_t> nodes) {
  switch (shape) {
    case Shape::kTetrahedron:
      return Faces(kTetFaces, nodes);
    case Shape::kHexahedron:
      return Faces(kHexFaces, nodes);
    case Shape::kPrism:
      return Faces(kPrismFaces, nodes);
    case Shape::kPyramid:
      return Faces(kPyramidFaces, nodes);
  }
  return {};
}

double SignedVolume(const Points& points, const std::vector<std::vector<int32_t>>& loops) {
  double six_volume = 0.0;
  for (const auto& loop : loops) {
    if (loop.empty()) continue;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int32_t v : loop) c += points.row(v).transpose();
    c /= static_cast<double>(loop.size());
    for (size_t i = 0; i < loop.size(); ++i) {
      const Eigen::Vector3d a = points.row(loop[i]).transpose();
      const Eigen::Vector3d b = points.row(loop[(i + 1) % loop.size()]).transpose();
      six_volume += c.dot(a.cross(b));
    }
  }
  return six_volume / 6.0;
}

}  // namespace dynsolid::io::internal
