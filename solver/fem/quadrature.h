// Gauss-Legendre quadrature on [0, 1] and tensor rules on the unit cube.
#pragma once

#include <vector>

#include <Eigen/Core>

namespace dynsolid::fem {

struct Rule1d {
  std::vector<double> points;   // in [0, 1]
  std::vector<double> weights;  // sum to 1
};

// n-point Gauss-Legendre rule on [0, 1], exact for polynomials of degree
// 2n - 1. n in [1, 8]; points by Newton iteration on P_n to machine precision.
Rule1d GaussLegendre(int n);

struct Rule3d {
  std::vector<Eigen::Vector3d> points;  // (u, v, w) in [0, 1]^3, u slowest
  std::vector<double> weights;          // sum to 1 (the cube's volume)
};

// Tensor product of the n-point rule in each direction.
Rule3d GaussLegendreCube(int n);

}  // namespace dynsolid::fem
