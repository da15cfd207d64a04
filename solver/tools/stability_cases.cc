#include "solver/tools/stability_cases.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/common/status_macros.h"
#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::stability {
namespace {

using Clock = std::chrono::steady_clock;

struct Grid {
  int nx, ny, nz;
  double length;  // along x
};

Grid GridOf(Shape shape) {
  switch (shape) {
    case Shape::kBlock:
      return {2, 1, 1, 2.0};
    case Shape::kThinLayer:
      return {3, 1, 1, 2.0 + kThinLayer};
    case Shape::kBeam:
      return {4, 1, 1, 2.0};
    case Shape::kLongBlock:
      return {4, 1, 1, 4.0};
  }
  return {1, 1, 1, 1.0};
}

std::string Vec(const Eigen::Vector3d& v) {
  return absl::StrFormat("x: %.17g y: %.17g z: %.17g", v.x(), v.y(), v.z());
}

// Signed volumes of the level-L cells (the FEM mesh) at node positions x:
// each face loop fanned into triangles about the cell's vertex average.
class CellVolumes {
 public:
  explicit CellVolumes(const mesh::CellComplex& fine) {
    std::vector<int32_t> loop;
    for (int32_t c = 0; c < fine.num_cells(); ++c) {
      const auto v = fine.cell_vertices(c);
      cell_vertices_.emplace_back(v.begin(), v.end());
      std::vector<std::array<int32_t, 3>> tris;
      for (int32_t f = 0; f < static_cast<int32_t>(fine.cell_faces(c).size()); ++f) {
        fine.CellFaceLoop(c, f, loop);
        for (size_t i = 1; i + 1 < loop.size(); ++i) tris.push_back({loop[0], loop[i], loop[i + 1]});
      }
      triangles_.push_back(std::move(tris));
    }
  }
  std::vector<double> Volumes(const Points& x) const {
    std::vector<double> out(triangles_.size());
    for (size_t c = 0; c < triangles_.size(); ++c) {
      Eigen::Vector3d o = Eigen::Vector3d::Zero();
      for (int32_t v : cell_vertices_[c]) o += x.row(v).transpose();
      o /= static_cast<double>(cell_vertices_[c].size());
      double vol = 0;
      for (const auto& t : triangles_[c]) {
        const Eigen::Vector3d a = x.row(t[0]).transpose() - o, b = x.row(t[1]).transpose() - o,
                              d = x.row(t[2]).transpose() - o;
        vol += a.dot(b.cross(d)) / 6.0;
      }
      out[c] = vol;
    }
    return out;
  }

 private:
  std::vector<std::vector<int32_t>> cell_vertices_;
  std::vector<std::vector<std::array<int32_t, 3>>> triangles_;
};

double MinRatio(const std::vector<double>& now, const std::vector<double>& rest) {
  double lo = INFINITY;
  for (size_t c = 0; c < now.size(); ++c) lo = std::min(lo, now[c] / rest[c]);
  return lo;
}

}  // namespace

const char* Name(Integrator integrator) {
  return integrator == Integrator::kBackwardEuler ? "backward_euler" : "central_difference";
}

std::string SceneText(const Case& c, Integrator integrator, int max_substeps) {
  std::string mesh;
  switch (c.shape) {
    case Shape::kBlock:
      mesh = "block { nx: 2 ny: 1 nz: 1 }";
      break;
    case Shape::kThinLayer:
      mesh = "block { nx: 3 ny: 1 nz: 1 }";  // reshaped by Build
      break;
    case Shape::kBeam:
      mesh = "beam { length: 2 width: 0.5 height: 0.5 cells_along: 4 cells_across: 1 }";
      break;
    case Shape::kLongBlock:
      mesh = "block { nx: 4 ny: 1 nz: 1 }";
      break;
  }
  const std::string end_box =
      "box { min { x: -0.01 y: -1 z: -1 } max { x: 0.01 y: 2 z: 2 } }";
  std::string constraints;
  if (c.penalty > 0) {
    constraints = absl::StrFormat("constraints { springs { region { %s } stiffness: %.17g } }",
                                  end_box, c.penalty);
  } else if (c.fixed_end) {
    constraints = absl::StrCat("constraints { fixed { ", end_box, " } }");
  }
  std::string loads, traced;
  for (size_t i = 0; i < c.loads.size(); ++i) {
    loads += absl::StrCat("point_forces { position { ", Vec(c.loads[i].position), " } force { ",
                          Vec(c.loads[i].force), " } } ");
    traced += absl::StrCat("traced { name: \"load", i, "\" position { ", Vec(c.loads[i].position),
                           " } } ");
  }
  if (c.gravity.squaredNorm() > 0) loads += absl::StrCat("gravity { ", Vec(c.gravity), " } ");
  std::string initial;
  if (c.spin.squaredNorm() > 0) {
    initial = absl::StrCat("initial { angular_velocity { ", Vec(c.spin), " } }");
  }
  return absl::StrFormat(R"pb(
    name: "%s"
    mesh { %s }
    subdivision { levels: %d }
    materials { base { young_modulus: %.17g poisson_ratio: %.17g density: %.17g } %s }
    %s
    loads { %s }
    %s
    %s
    solver { model: COROTATIONAL integrator: %s time_step: %.17g max_substeps: %d }
  )pb", c.name, mesh, c.levels, c.young, c.poisson, c.density, c.regions, constraints, loads,
                         initial, traced,
                         integrator == Integrator::kBackwardEuler ? "BACKWARD_EULER"
                                                                  : "CENTRAL_DIFFERENCE",
                         c.h, max_substeps);
}

absl::StatusOr<std::unique_ptr<solid::Solid>> Build(const Case& c, Integrator integrator,
                                                     int max_substeps) {
  ASSIGN_OR_RETURN(const Scene scene, scene::ParseScene(SceneText(c, integrator, max_substeps), c.name));
  ASSIGN_OR_RETURN(mesh::MeshInput input, scene::ControlMeshInput(scene, ""));
  if (c.shape == Shape::kThinLayer) {
    // x = 0, 1, 1 + t, 2 + t: the middle layer of cells is t thick.
    for (Eigen::Index i = 0; i < input.vertices.rows(); ++i) {
      const double x = input.vertices(i, 0);
      if (x > 1.5) input.vertices(i, 0) = x - 1.0 + kThinLayer;
    }
  }
  ASSIGN_OR_RETURN(scene::Discretization d, scene::Discretize(scene, input, std::nullopt));
  return solid::Solid::Create(scene, std::move(d));
}

Points Twisted(const Points& rest, double radians, double length, double y0, double z0) {
  Points p = rest;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    const double a = radians * rest(i, 0) / length;
    const double y = rest(i, 1) - y0, z = rest(i, 2) - z0;
    p(i, 1) = y0 + std::cos(a) * y - std::sin(a) * z;
    p(i, 2) = z0 + std::sin(a) * y + std::cos(a) * z;
  }
  return p;
}

std::string Outcome::Verdict() const {
  if (!always_finite) return "non-finite";
  if (!create.ok()) return "refused";
  if (!final_status.ok()) return "stopped";
  const double ratio = std::isfinite(central_energy_ratio) ? central_energy_ratio : energy_ratio;
  if (ratio > 1 + kEnergyTolerance) {
    return late_growth_ratio > 1 + kGrowthTolerance ? "growing" : "bounded rise";
  }
  return rollbacks > 0 ? "stable after rollbacks" : "stable";
}

Outcome RunCase(const Case& c, Integrator integrator, const RunOptions& options) {
  Outcome out;
  const int steps = options.steps;
  out.steps = steps;
  const auto t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<solid::Solid>> built = Build(c, integrator, options.max_substeps);
  out.create = built.status();
  if (!built.ok()) {
    out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
    return out;
  }
  solid::Solid& s = **built;
  const Grid grid = GridOf(c.shape);
  const Points rest = s.control_positions();
  if (c.twist != 0) {
    const double y0 = c.shape == Shape::kBeam ? 0.0 : 0.5, z0 = y0;
    s.SetAtRest(Twisted(rest, c.twist, grid.length, y0, z0));
  }
  if (options.force_substeps > 0) s.SetSubstepsForTesting(options.force_substeps);
  out.stable_step = s.build_report().stable_step;
  out.substeps_start = s.build_report().substeps;
  // The control points' shares of the mass (gravity's work) and the springs.
  const Points mass = s.ApplyMass(Points::Ones(rest.rows(), 3));
  std::vector<int> springs;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    if (c.penalty > 0 && std::abs(rest(i, 0)) <= 0.01) springs.push_back(static_cast<int>(i));
  }
  const std::vector<Eigen::Vector3d> traced0 = s.TracedPositionsAt(rest);
  auto energy = [&](double strain, double kinetic, double* mech) {
    const Points& p = s.control_positions();
    double spring = 0, work = 0;
    for (int i : springs) spring += 0.5 * c.penalty * (p.row(i) - rest.row(i)).squaredNorm();
    const std::vector<Eigen::Vector3d> traced = s.TracedPositions();
    for (size_t k = 0; k < c.loads.size(); ++k) work += c.loads[k].force.dot(traced[k] - traced0[k]);
    if (c.gravity.squaredNorm() > 0) {
      for (Eigen::Index i = 0; i < p.rows(); ++i) {
        work += mass(i, 0) * c.gravity.dot((p.row(i) - rest.row(i)).transpose());
      }
    }
    *mech = kinetic + strain + spring;
    return *mech - work;
  };
  auto finite = [&] {
    if (!s.control_positions().allFinite()) return false;
    for (const Eigen::Vector3d& x : s.TracedPositions()) {
      if (!x.allFinite()) return false;
    }
    const solid::Energies e = s.ComputeEnergies();
    return std::isfinite(e.kinetic) && std::isfinite(e.strain);
  };
  double mech = 0;
  const double strain0 = c.twist != 0 ? s.StrainEnergy(s.control_positions()) : 0.0;
  const double h0 = energy(strain0, s.ComputeEnergies().kinetic, &mech);
  out.initial_energy = h0;
  out.peak_mechanical = mech;
  double h_max = h0, h_end = h0;
  const CellVolumes volumes(s.discretization().fine());
  const std::vector<double> rest_volumes = volumes.Volumes(s.NodePositions());
  out.min_volume_ratio = MinRatio(volumes.Volumes(s.NodePositions()), rest_volumes);
  // Central-difference energy with the central velocity (p_{n+1} -
  // p_{n-1}) / 2h at step n, available while every step is one sub-step.
  Points p_before = s.control_positions(), p_now = p_before;
  double potential_now = 0;  // H - kinetic at p_now
  double hc_max = -INFINITY;
  bool central = integrator == Integrator::kCentralDifference;
  for (int i = 0; i < steps; ++i) {
    out.final_status = s.Step();
    if (!finite()) {
      out.always_finite = false;
      break;
    }
    if (!out.final_status.ok()) break;
    ++out.steps_done;
    const solid::Energies e = s.ComputeEnergies();
    h_end = energy(e.strain, e.kinetic, &mech);
    h_max = std::max(h_max, h_end);
    central = central && s.build_report().substeps == 1 && s.last_step().rollbacks == 0;
    if (central && i >= 1) {
      const Points v = (s.control_positions() - p_before) / (2 * c.h);
      const double kinetic = 0.5 * (v.array() * s.ApplyMass(v).array()).sum();
      hc_max = std::max(hc_max, kinetic + potential_now);
    }
    p_before = p_now;
    p_now = s.control_positions();
    potential_now = h_end - e.kinetic;
    out.energy.push_back(h_end);
    out.peak_mechanical = std::max(out.peak_mechanical, mech);
    out.min_volume_ratio =
        std::min(out.min_volume_ratio, MinRatio(volumes.Volumes(s.NodePositions()), rest_volumes));
    out.max_displacement = std::max(
        out.max_displacement, (s.control_positions() - rest).rowwise().norm().maxCoeff());
  }
  const double scale = out.peak_mechanical > 0 ? out.peak_mechanical : 1.0;
  out.energy_ratio = 1 + (h_max - h0) / scale;
  out.final_energy_ratio = 1 + (h_end - h0) / scale;
  out.central_energy_ratio =
      central && std::isfinite(hc_max) ? 1 + (std::max(hc_max, h0) - h0) / scale : NAN;
  const size_t half = out.energy.size() / 2;
  double first = h0, second = -INFINITY;
  for (size_t i = 0; i < out.energy.size(); ++i) {
    (i < half ? first : second) = std::max(i < half ? first : second, out.energy[i]);
  }
  out.late_growth_ratio = out.energy.empty() ? 1.0 : 1 + (second - first) / scale;
  out.rollbacks = s.rollbacks();
  out.substeps_end = s.build_report().substeps;
  out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

std::vector<Case> Cases() {
  std::vector<Case> cases;
  const Eigen::Vector3d down(0, 0, -9.81);
  for (double e : {1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10}) {
    Case c;
    c.name = absl::StrFormat("young_%.0e", e);
    c.what = absl::StrFormat("E = %.0e Pa, clamped block, tip load 1e-4 E (same strain for every E)", e);
    c.young = e;
    c.loads = {{{1.9, 0.5, 0.5}, {0, 0, -1e-4 * e}}};
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "poisson_0.499";
    c.what = "nearly incompressible (nu = 0.499), E = 1e6 Pa, clamped block under gravity";
    c.poisson = 0.499;
    c.gravity = down;
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "penalty_1e9";
    c.what = "block held at one end by penalty springs of 1e9 N/m (E = 1e7 Pa), gravity";
    c.young = 1e7;
    c.fixed_end = false;
    c.penalty = 1e9;
    c.gravity = down;
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "inverting_load";
    c.what = "E = 1e3 Pa, 1e3 N pushing the free end towards the clamp (inverts cells)";
    c.young = 1e3;
    c.loads = {{{1.9, 0.5, 0.5}, {-1e3, 0, 0}}};
    c.duration = 3;  // the cells invert after about a second
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "spin_10_rad_s";
    c.what = "free block spinning at 10 rad/s about z, E = 1e6 Pa";
    c.fixed_end = false;
    c.spin = Eigen::Vector3d(0, 0, 10);
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "twist_180";
    c.what = "beam 2 x 0.5 x 0.5 m, E = 1e6 Pa, clamped, released from a 180-degree twist";
    c.shape = Shape::kBeam;
    c.twist = M_PI;
    cases.push_back(c);
  }
  for (int levels : {0, 1}) {
    Case c;
    c.name = absl::StrCat("thin_layer_L", levels);
    c.what = absl::StrCat(
        "a control cell 1e-3 m thick between 1 m cells (near-degenerate), E = 1e7 Pa, gravity, ",
        levels, levels == 0 ? " levels (the thin cell is an element)"
                            : " level (subdivision smooths the thin cell)");
    c.shape = Shape::kThinLayer;
    c.levels = levels;
    c.young = 1e7;
    c.gravity = down;
    cases.push_back(c);
  }
  {
    Case c;
    c.name = "density_ratio_1e6";
    c.what = "4 m block, densities 1 and 1e6 kg/m^3 painted on its halves, E = 1e10 Pa, gravity";
    c.shape = Shape::kLongBlock;
    c.young = 1e10;
    c.density = 1;
    c.regions =
        "regions { region { box { min { x: 2 y: -1 z: -1 } max { x: 5 y: 2 z: 2 } } } "
        "material { young_modulus: 1e10 density: 1e6 } }";
    c.gravity = down;
    cases.push_back(c);
  }
  return cases;
}

}  // namespace dynsolid::stability
