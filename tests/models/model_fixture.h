// What the model tests build alike: a built-in scene's discretization at
// some levels, its FEM nodes at rest and an element layout, plus random
// node vectors and their dot product.
#pragma once

#include <cstdint>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "solver/models/element_blocks.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::models::test_util {

struct MeshFixture {
  scene::Discretization d;
  Points rest;  // A p at the control mesh's rest positions
  ElementLayout layout;
};

// Fills `f` from `scene` at `levels`, the layout sampled by `sampler`.
inline void BuildMesh(const absl::StatusOr<Scene>& scene, int levels,
                      const MaterialSampler& sampler, MeshFixture& f) {
  EXPECT_OK(scene);
  auto d = scene::BuildDiscretization(*scene, scene::BuiltinSceneDir(), levels);
  EXPECT_OK(d);
  f.d = *std::move(d);
  f.rest = f.d.node_matrix * f.d.control().positions();
  f.layout = BuildElementLayout(f.d.elements, f.rest, f.d.hierarchy.control_cell, sampler);
}

// Stiffer where x > 0.5 (Young's modulus 2 young there, young elsewhere):
// groups then differ by material as well.
inline MaterialSampler TwoMaterials(double young, double poisson) {
  return [young, poisson](const Eigen::Vector3d& x, int32_t) {
    return MaterialPoint{x.x() > 0.5 ? 2 * young : young, poisson, 1000, 0};
  };
}

// rows x 3 standard normal entries from `seed`.
inline Points RandomPoints(int64_t rows, uint32_t seed) {
  std::mt19937 gen(seed);
  std::normal_distribution<double> normal;
  Points v(rows, 3);
  for (int64_t i = 0; i < v.size(); ++i) v.data()[i] = normal(gen);
  return v;
}

inline double Dot(const Points& a, const Points& b) { return (a.array() * b.array()).sum(); }

}  // namespace dynsolid::models::test_util
