// What the solid tests share: solids from scene text, the centre of mass,
// and the free block and cantilever scenes.
#pragma once

#include <memory>
#include <string>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "solver/solid/solid.h"
#include "tests/testing/make_solid.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::solid {

using ::dynsolid::testing::Parse;
using ::dynsolid::testing::StatusIs;
using ::testing::HasSubstr;

inline std::unique_ptr<Solid> Make(const std::string& text) { return testing::MakeSolid(text); }

// Two solids of the same `text`: one to change, one to compare it with.
inline void MakeTwins(const std::string& text, std::unique_ptr<Solid>* a,
                      std::unique_ptr<Solid>* b) {
  *a = Make(text);
  *b = Make(text);
  ASSERT_NE(*a, nullptr);
  ASSERT_NE(*b, nullptr);
}

// Centre of mass from the row sums of Mt.
inline Eigen::Vector3d Centre(const Solid& s) {
  const Points& p = s.control_positions();
  const Points w = s.ApplyMass(Points::Ones(p.rows(), 3));
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int64_t i = 0; i < p.rows(); ++i) c += w(i, 0) * p.row(i).transpose();
  return c / s.total_mass();
}

// A free 2 m cube of 2 x 2 x 2 cells at one level.
inline constexpr char kFreeBlock[] = R"pb(
  mesh { block { nx: 2 ny: 2 nz: 2 } }
  subdivision { levels: 1 }
  materials { base { young_modulus: 1e4 density: 100 } }
  solver { time_step: 1e-3 cg_tolerance: 1e-13 }
)pb";

// A damped 1 m cantilever of `cells_along` cells (0.1 m square, one level,
// clamped at x = 0) under `loads`, its tip at x = 1 traced.
inline std::string Cantilever(int cells_along, const std::string& loads) {
  return absl::StrCat(R"pb(
    mesh { beam { length: 1 width: 0.1 height: 0.1 cells_along: )pb",
                      cells_along, R"pb( cells_across: 1 } }
    subdivision { levels: 1 }
    sharp { crease_angle_degrees: 60 }
    materials { base { young_modulus: 1e6 density: 1000 damping: 3000 } }
    constraints { fixed { box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 1 z: 1 } } } }
    loads { )pb", loads, R"pb( }
    traced { name: "tip" position { x: 1 y: 0 z: 0 } }
    solver { time_step: 1e-3 }
  )pb");
}

// The cantilever under gravity, of 6 cells.
inline const std::string kBeam = Cantilever(6, "gravity { z: -9.81 }");

}  // namespace dynsolid::solid
