// A matrix of uniform random entries in [-1, 1) drawn from a seed, for the
// models' tests of products against Eigen's.
#pragma once

#include <cstdint>
#include <random>

#include <Eigen/Core>

namespace dynsolid::models {

inline Eigen::MatrixXd RandomMatrix(int64_t rows, int cols, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd m(rows, cols);
  for (int j = 0; j < cols; ++j)
    for (int64_t i = 0; i < rows; ++i) m(i, j) = u(rng);
  return m;
}

}  // namespace dynsolid::models
