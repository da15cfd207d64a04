// Material painting (the paper's brush on material properties): a paint is
// prepared off the simulation loop (PreparePaint: the new material layout,
// its matrices, mass and stable step on a model of its own) and installed
// on it (ApplyPaint); PaintMaterial is the two in a row.
#include <algorithm>
#include <array>
#include <memory>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

// smoothstep(t) = t^2 (3 - 2 t) on [0, 1].
double Smoothstep(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// The paint weight of a sample at rest position x in control cell `cell`
// (scene.proto MaterialPaint).
double PaintWeight(const MaterialPaint& paint, const Eigen::Vector3d& x, int32_t cell) {
  const Region& r = paint.region();
  double w = 0;
  for (int32_t c : r.control_cells()) {
    if (c == cell) w = paint.strength();
  }
  double depth = -1, band = 0;
  const double falloff = paint.falloff() > 0 ? paint.falloff() : 0.25;
  if (r.shape_case() == Region::kSphere) {
    depth = r.sphere().radius() - (x - V(r.sphere().center())).norm();
    band = falloff * r.sphere().radius();
  } else if (r.shape_case() == Region::kBox) {
    const Eigen::Vector3d lo = V(r.box().min()), hi = V(r.box().max());
    depth = std::min((x - lo).minCoeff(), (hi - x).minCoeff());
    band = falloff * 0.5 * (hi - lo).minCoeff();
  }
  if (depth >= 0) {
    const double s = band > 0 ? Smoothstep(depth / band) : 1.0;
    w = std::max(w, paint.strength() * s);
  }
  return w;
}

double Blend(double value, double target, double w) {
  if (target == 0 || w <= 0) return value;  // unset fields are not painted
  if (w >= 1) return target;
  return value + w * (target - value);
}

// Clay's flow laws per control cell after `paint` (weights at the cells'
// rest centroids). A preset paints all three fields, zeros included (rubber
// stops a cell from yielding); otherwise only the fields set.
std::vector<material::FlowLaw> PaintedLaws(const MaterialPaint& paint, const Material& target,
                                           std::vector<material::FlowLaw> laws,
                                           const mesh::CellComplex& control) {
  const bool all = paint.material().preset() != Material::PRESET_NONE;
  auto blend = [&](double value, double to, double w) {
    if (!all) return Blend(value, to, w);
    if (w <= 0) return value;
    return w >= 1 ? to : value + w * (to - value);
  };
  for (int32_t c = 0; c < control.num_cells(); ++c) {
    const double w = PaintWeight(paint, control.CellCentroid(c), c);
    material::FlowLaw& l = laws[c];
    l.yield = blend(l.yield, target.yield_strain(), w);
    l.rate = blend(l.rate, target.flow_rate(), w);
    l.hardening = blend(l.hardening, target.hardening(), w);
    if (target.poisson_ratio() > 0) l.poisson = Blend(l.poisson, target.poisson_ratio(), w);
    if (l.yield > 0 && l.rate == 0) l.rate = scene::kDefaultFlowRate;
  }
  return laws;
}

}  // namespace

// ---- Material painting.

absl::Status Solid::PaintMaterial(const MaterialPaint& paint) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedPaint> prepared, PreparePaint(paint));
  return ApplyPaint(*prepared);
}

absl::StatusOr<std::shared_ptr<Solid::PreparedPaint>> Solid::PreparePaint(
    const MaterialPaint& paint) const {
  const Impl& im = *impl_;
  const auto t_start = Clock::now();
  RETURN_IF_ERROR(scene::ValidateMaterialPaint(paint, "paint"));
  RETURN_IF_ERROR(im.CheckControlCells(paint.region(), "paint.region"));
  auto out = std::make_shared<PreparedPaint>();
  out->paint = paint;
  out->made_for = im.PreparedForNow();

  const models::ElementLayout& old = *im.layout;
  const Material target = scene::WithPreset(paint.material());
  {
    const Material& m = paint.material();
    out->paints_flow = m.yield_strain() > 0 || m.flow_rate() > 0 || m.hardening() > 0 ||
                       m.preset() != Material::PRESET_NONE;
  }
  if (out->paints_flow) {
    std::vector<material::FlowLaw> now =
        im.plasticity != nullptr ? im.plasticity->laws()
                                 : std::vector<material::FlowLaw>(d_.control().num_cells());
    out->laws = PaintedLaws(paint, target, std::move(now), d_.control());
    const bool yields = std::any_of(out->laws.begin(), out->laws.end(),
                                    [](const material::FlowLaw& l) { return l.yield > 0; });
    if (yields && im.cell_model == nullptr && im.corotational == nullptr) {
      return absl::InvalidArgumentError(
          "paint.material.yield_strain: painting clay (a material that yields) needs "
          "solver.model COROTATIONAL (the paper's local-frame model does not carry plastic "
          "flow)");
    }
  }
  int64_t touched = 0;
  // Bounds for the new stable step: K' <= r K and M' >= m M in the PSD
  // sense, r the largest ratio of the isotropic stiffness's eigenvalues
  // (3 lambda + 2 mu, lambda + 2 mu, mu: the same eigenvectors for every
  // isotropic C, and the local-frame model's diagonal blocks use the last
  // two) and m the smallest density ratio over the samples; unpainted
  // samples have ratio 1. Then omega'^2 <= omega^2 r / m.
  double stiffness_ratio = 1, mass_ratio = 1;
  auto stiffness_ratios = [](const models::MaterialPoint& a, const models::MaterialPoint& b) {
    const double la = a.lame_lambda(), ma = a.lame_mu(), lb = b.lame_lambda(), mb = b.lame_mu();
    return std::max({(3 * lb + 2 * mb) / (3 * la + 2 * ma), (lb + 2 * mb) / (la + 2 * ma), mb / ma});
  };
  // Only elements whose rest box (Impl::element_boxes) meets the region,
  // or whose control cell it lists, can hold a painted sample: every shape
  // function is non-negative inside its element, so its samples lie in
  // that box.
  const Region& r = paint.region();
  std::vector<uint8_t> listed(d_.control().num_cells(), 0);
  for (int32_t c : r.control_cells()) listed[c] = 1;
  Eigen::AlignedBox3d region;  // empty: no shape
  if (r.shape_case() == Region::kSphere) {
    const Eigen::Vector3d c = V(r.sphere().center());
    region = Eigen::AlignedBox3d(c.array() - r.sphere().radius(), c.array() + r.sphere().radius());
  } else if (r.shape_case() == Region::kBox) {
    region = Eigen::AlignedBox3d(V(r.box().min()), V(r.box().max()));
  }
  const std::vector<int32_t>& control_cell = d_.hierarchy.control_cell;
  std::array<std::vector<int32_t>, 3> painted;  // per element: index into arrays, or -1
  std::vector<std::vector<models::MaterialPoint>> arrays;
  fem::NodeMatrixX3 x;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = old.blocks[kind];
    const fem::KindTable& table = old.tables[kind];
    const int n = block.nodes;
    painted[kind].assign(block.size(), -1);
    x.resize(n, 3);
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t cell = control_cell.empty() ? block.cell[e] : control_cell[block.cell[e]];
      if (!listed[cell] && !im.element_boxes[kind][e].intersects(region)) continue;
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < n; ++i) x.row(i) = im.rest_nodes.row(ids[i]);
      const std::vector<models::MaterialPoint>& was = old.materials[block.groups[block.group[e]].material];
      std::vector<models::MaterialPoint> now = was;
      bool changed = false;
      for (int q = 0; q < table.points; ++q) {
        const double w = PaintWeight(paint, models::SamplePosition(table, q, x), cell);
        if (!(w > 0)) continue;
        ++touched;
        models::MaterialPoint& m = now[q];
        m.young = Blend(m.young, target.young_modulus(), w);
        m.poisson = Blend(m.poisson, target.poisson_ratio(), w);
        m.density = Blend(m.density, target.density(), w);
        m.damping = Blend(m.damping, target.damping(), w);
        stiffness_ratio = std::max(stiffness_ratio, stiffness_ratios(was[q], m));
        mass_ratio = std::min(mass_ratio, m.density / was[q].density);
        changed |= !(m == was[q]);
      }
      if (changed) {
        painted[kind][e] = static_cast<int32_t>(arrays.size());
        arrays.push_back(std::move(now));
      }
    }
  }
  auto layout = std::make_unique<models::ElementLayout>(models::RelayoutMaterials(
      old, im.rest_nodes, [&](int kind, int32_t e) -> const std::vector<models::MaterialPoint>* {
        const int32_t a = painted[kind][e];
        return a < 0 ? nullptr : &arrays[a];
      }));
  if (touched == 0) {
    return absl::InvalidArgumentError(
        "paint.region contains no material sample (quadrature point) of the solid");
  }
  out->samples_painted = touched;
  out->layout_ms = MsSince(t_start);
  // The new model's passes (the stable-step estimate below) run on a pool
  // of this thread's own: the solid's may be stepping.
  out->pool = std::make_unique<WorkerPool>(1);
  ASSIGN_OR_RETURN(out->build,
                   im.BuildMaterial(std::move(layout), /*reuse=*/true, out->pool.get()));
  // The stable step: from the bound when it keeps the sub-step count (or
  // the step is implicit), else estimated afresh (Lanczos, the
  // costliest part of a paint). Sub-steps never drop on a paint.
  const auto t_stable = Clock::now();
  double omega = im.omega_max * std::sqrt(stiffness_ratio / mass_ratio);
  int substeps = im.use_implicit ? im.MinSubsteps() : std::max(im.substeps, im.SubstepsFor(omega));
  if (!im.use_implicit && substeps > im.substeps) {
    omega = im.EstimateOmegaMax(*out->build.model, out->build.mt, im.fixed, nullptr,
                                out->build.cell_model.get(), out->pool.get());
    out->estimated = true;
    substeps = std::max(im.substeps, im.SubstepsFor(omega));
  }
  if (substeps > im.settings.max_substeps()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "paint: the painted solid needs ", substeps, " explicit sub-steps (stable step ",
        2.0 / omega, " s) but solver.max_substeps is ", im.settings.max_substeps(),
        "; paint a softer or denser material, or lower the time step"));
  }
  out->omega = omega;
  out->substeps = substeps;
  out->stable_ms = MsSince(t_stable);
  if (im.use_implicit) {
    out->k0 = im.StiffnessMatrix(*out->build.layout, *out->build.corotational, *out->pool,
                                 &out->k0_cells, out->build.k_cells.get());
    // The float copies of the element matrices, here rather than when
    // installed (ConfigureLinearized then finds them made).
    out->build.corotational->SetSinglePrecisionLinearized(im.SinglePrecisionLinearized());
    // The integrator's matrices and factors (a paint keeps one sub-step).
    out->implicit_setup = integrators::BackwardEuler::Prepare(
        out->build.mt, out->build.has_damping ? &out->build.dt : nullptr, h_, im.fixed, &out->k0);
  }
  out->total_ms = MsSince(t_start);
  return out;
}

Solid::PaintPhases Solid::PhasesOf(const PreparedPaint& prepared) {
  PaintPhases out;
  out.layout = prepared.layout_ms;
  out.model = prepared.build.model_ms;
  out.mass = prepared.build.mass_ms;
  out.stable = prepared.stable_ms;
  out.total = prepared.total_ms;
  out.cells_made = prepared.build.k_cells_made;
  out.samples_painted = prepared.samples_painted;
  return out;
}

absl::Status Solid::ApplyPaint(PreparedPaint& prepared) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedPaint> again;
  PreparedPaint* p = &prepared;
  if (prepared.build.model == nullptr || prepared.made_for != im.PreparedForNow()) {
    // Prepared for a material, stable step or fixed set that has changed
    // since (or used up): the same paint on the current solid.
    ASSIGN_OR_RETURN(again, PreparePaint(prepared.paint));
    p = again.get();
  }
  MaterialBuild& build = p->build;
  const double omega = p->omega;
  const int substeps = p->substeps;
  const bool estimated = p->estimated;
  // Nothing can fail from here on.
  build.model->set_frames(im.model->frames());
  build.model->set_pool(*im.pool);
  if (p->paints_flow && im.plasticity == nullptr) {
    // The first clay on this solid: its part, attached by InstallMaterial.
    im.plasticity = std::make_unique<material::Plasticity>(p->laws);
  } else if (p->paints_flow) {
    im.plasticity->set_laws(p->laws);
  }
  im.InstallMaterial(std::move(build));
  if (im.use_implicit) {
    im.k0 = std::move(p->k0);
    im.k0_cells = std::move(p->k0_cells);
  }
  im.omega_max = omega;
  if (estimated) im.omega_fixed = im.fixed;  // a bound holds for the old estimate's set
  im.stable_step = omega > 0 ? 2.0 / omega : INFINITY;
  const double old_h = im.h_sub;
  im.SetSubsteps(substeps, h_, &p->implicit_setup);
  if (im.h_sub != old_h) p_prev_ = p_ - (im.h_sub / old_h) * (p_ - p_prev_);  // keep the velocity
  im.RebuildConstantLoads();  // gravity follows the density
  total_mass_ = SumOfValues(im.mt);
  ReportMaterial();
  report_.omega_max = im.omega_max;
  report_.stable_step = im.stable_step;
  report_.substeps = im.substeps;
  im.forces_valid = false;
  im.ledger.RequestRebase();
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
