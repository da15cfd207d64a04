#include "solver/solid/load_bounds.h"

#include <cfloat>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace dynsolid::solid {
namespace {

constexpr double kMostSizes = 10;  // u at most 10 L

// One check: `u_per_unit` the static displacement of a unit load, `rigid_per_unit`
// the rigid displacement over 1 s of a unit load on the free solid.
absl::Status Check(const LoadScale& s, double magnitude, std::string_view field,
                   std::string_view unit, std::string_view estimate, double u_per_unit,
                   double rigid_per_unit) {
  if (!(s.size > 0) || !(s.young > 0) || !(u_per_unit > 0)) return absl::OkStatus();
  const double a = std::abs(magnitude);
  if (a == 0) return absl::OkStatus();
  const double most = kMostSizes * s.size / u_per_unit;
  if (a > most) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: %.3g %s is far beyond what this solid can take: it would move it about %.3g m "
        "(static estimate %s with E = %.3g Pa, L = %.3g m), more than %g times its size; the "
        "largest this solid takes is %.3g %s",
        field, a, unit, a * u_per_unit, estimate, s.young, s.size, kMostSizes, most, unit));
  }
  const double ulp = DBL_EPSILON * s.size;
  if (a * u_per_unit < ulp && a * rigid_per_unit < ulp) {
    const double least = ulp / std::max(u_per_unit, rigid_per_unit);
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: %.3g %s would have no effect in double precision: it moves this solid less than "
        "one unit in the last place of its size (%.3g m); the least that moves it is about "
        "%.3g %s",
        field, a, unit, ulp, least, unit));
  }
  return absl::OkStatus();
}

// The diagonal of the points' bounding box (0 without points).
double Extent(const Points& p) {
  if (p.rows() == 0) return 0;
  return (p.colwise().maxCoeff() - p.colwise().minCoeff()).norm();
}

}  // namespace

double MeanYoung(const models::ElementLayout& layout) {
  double young = 0;
  int64_t samples = 0;
  for (const auto& array : layout.materials) {
    for (const models::MaterialPoint& m : array) young += m.young;
    samples += static_cast<int64_t>(array.size());
  }
  return samples > 0 ? young / static_cast<double>(samples) : 0;
}

LoadScale ScaleOf(const Points& rest_control, const models::ElementLayout& layout, double mass,
                  double rest_volume) {
  LoadScale s;
  s.size = Extent(rest_control);
  s.young = MeanYoung(layout);
  s.mass = mass;
  s.density = rest_volume > 0 ? mass / rest_volume : 0;
  return s;
}

absl::Status CheckForce(const LoadScale& s, double magnitude, std::string_view field) {
  // A free solid of mass m moves F / (2 m) in one second.
  return Check(s, magnitude, field, "N", "|F| / (E L)", 1.0 / (s.young * s.size),
               s.mass > 0 ? 0.5 / s.mass : 0);
}

absl::Status CheckPressure(const LoadScale& s, double magnitude, std::string_view field) {
  // On a face of about L^2: P L^2 / (2 m) in one second.
  return Check(s, magnitude, field, "Pa", "|P| L / E", s.size / s.young,
               s.mass > 0 ? 0.5 * s.size * s.size / s.mass : 0);
}

absl::Status CheckGravity(const LoadScale& s, double magnitude, std::string_view field) {
  // Every solid falls g / 2 in one second.
  return Check(s, magnitude, field, "m/s^2", "rho |g| L^2 / E",
               s.density * s.size * s.size / s.young, 0.5);
}

absl::Status CheckExtent(const Points& rest_control, const Points& p) {
  if (rest_control.rows() == 0 || p.rows() == 0) return absl::OkStatus();
  const double rest = Extent(rest_control);
  const double now = Extent(p);
  if (now <= kMostSizes * rest) return absl::OkStatus();
  return absl::InternalError(absl::StrFormat(
      "the solid blew up: its control points spread over %.3g m, more than %g times their "
      "rest extent of %.3g m",
      now, kMostSizes, rest));
}

}  // namespace dynsolid::solid
