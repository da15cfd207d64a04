// Loads within physics: the bounds a solid puts on the loads it is given,
// derived from the solid itself (its size, stiffness and density), not
// from constants. A room of its own with no state: the bounds are computed
// from the solid's scale when a load arrives.
//
// A load's size is its static displacement estimate u against the solid's
// size L (its rest bounding box's diagonal), for the solid's mean sampled
// Young's modulus E and density rho (a body of size L is about E L stiff):
//
//   point force F:      u = F / (E L)
//   pressure P:         u = P L / E
//   gravity g:          u = rho g L^2 / E
//
// A load with u > 10 L could only tear the solid apart (linear elasticity
// has nothing to say there): it is refused, naming the largest value the
// solid takes. A load too small to move anything in double precision, with
// both u and the rigid motion it gives a free solid over one second below
// one ulp of the solid's size (2^-52 L), is refused too: it would be kept,
// journaled and shown, and do nothing. Zero is a load's "off" and passes.
#pragma once

#include <string_view>

#include "absl/status/status.h"
#include "solver/mesh/points.h"
#include "solver/models/element_blocks.h"

namespace dynsolid::solid {

struct LoadScale {
  double size = 0;     // L, m
  double young = 0;    // E, Pa (mean over the material samples)
  double density = 0;  // rho, kg/m^3 (total mass / rest volume)
  double mass = 0;     // kg
};

// The mean Young's modulus over a layout's material samples (Pa; 0 without
// samples).
double MeanYoung(const models::ElementLayout& layout);

// The scale of a solid from its control points at rest, its element layout
// (material samples), total mass and rest volume.
LoadScale ScaleOf(const Points& rest_control, const models::ElementLayout& layout, double mass,
                  double rest_volume);

// Whether a load of `magnitude` (N, Pa or m/s^2) is within the bounds
// above; InvalidArgument naming `field`, the estimate and the bound.
absl::Status CheckForce(const LoadScale& s, double magnitude, std::string_view field);
absl::Status CheckPressure(const LoadScale& s, double magnitude, std::string_view field);
absl::Status CheckGravity(const LoadScale& s, double magnitude, std::string_view field);

// Whether a state is still within physics: its control points' extent (the
// diagonal of their bounding box) at most 10 times their rest extent, the
// same bound as the loads'. Rigid motion and rotation keep the extent (a
// rotation grows a box's diagonal by at most sqrt(3)); a blow-up passes the
// bound within steps, even one that a follower pressure pays for and the
// energy ledger therefore lets through. InternalError saying both extents.
absl::Status CheckExtent(const Points& rest_control, const Points& p);

}  // namespace dynsolid::solid
