// The solid's parts with state of their own, as the solid makes, saves and
// restores them: clay (material/plasticity.h) and the environment
// (contact/obstacle_contact.h). Each part keeps its own state; the solid
// only builds it, hands it positions and forces, and carries its bytes.
#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/load_bounds.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {

std::vector<material::FlowLaw> Solid::Impl::SceneFlowLaws(const Scene& scene) const {
  const mesh::CellComplex& control = d->control();
  std::vector<material::FlowLaw> laws(control.num_cells());
  for (int32_t c = 0; c < control.num_cells(); ++c) {
    const Eigen::Vector3d x = control.CellCentroid(c);
    const Material* m = &scene.materials().base();
    for (const MaterialRegion& r : scene.materials().regions()) {
      if (InRegion(r.region(), x, c)) m = &r.material();
    }
    laws[c] = material::FlowLawOf(scene::ResolvedMaterial(*m));
  }
  return laws;
}

absl::Status Solid::Impl::MakePlasticity(const Scene& scene) {
  std::vector<material::FlowLaw> laws = SceneFlowLaws(scene);
  if (std::none_of(laws.begin(), laws.end(), [](const material::FlowLaw& l) { return l.yield > 0; })) {
    return absl::OkStatus();
  }
  // (The scene's rules refuse it first, naming the field.)
  if (cell_model == nullptr && corotational == nullptr) {
    return absl::InvalidArgumentError(
        "materials: a material that yields needs solver.model COROTATIONAL");
  }
  plasticity = std::make_unique<material::Plasticity>(std::move(laws));
  AttachPlasticity();
  return absl::OkStatus();
}

void Solid::Impl::AttachPlasticity() {
  if (plasticity == nullptr) {
    if (cell_model != nullptr) cell_model->set_flow(nullptr);
    if (corotational != nullptr) corotational->set_flow(nullptr);
    return;
  }
  if (cell_model != nullptr) {
    plasticity->Attach(*cell_model);
  } else if (corotational != nullptr) {
    plasticity->Attach(*corotational, d->hierarchy.control_cell);
  }
}

material::Plasticity::Units Solid::Impl::PlasticUnits() const {
  if (cell_model != nullptr) return material::Plasticity::UnitsOf(*cell_model);
  if (corotational != nullptr) return material::Plasticity::UnitsOf(*layout);
  return {};
}

int32_t Solid::Impl::CarryPlasticity(const Impl& old, const std::vector<int32_t>& point_source,
                                     const std::vector<int32_t>& cell_source) {
  if (plasticity == nullptr || old.plasticity == nullptr) return 0;
  const int32_t units = plasticity->units();
  std::vector<int32_t> source(units, -1);
  std::vector<std::vector<int32_t>> entry_map(units);
  if (cell_model != nullptr && old.cell_model != nullptr) {
    // Control cells: the same support points, in the old cell's order.
    for (int32_t c = 0; c < cell_model->cells(); ++c) {
      const int32_t src = cell_source[c];
      if (src < 0 || src >= old.cell_model->cells()) continue;
      const int32_t n = cell_model->support_size(c);
      if (old.cell_model->support_size(src) != n) continue;
      const int32_t* now = cell_model->support(c);
      const int32_t* was = old.cell_model->support(src);
      std::vector<int32_t> map(n);
      bool same = true;
      for (int32_t a = 0; a < n && same; ++a) {
        const int32_t o = point_source[now[a]];
        const int32_t* at = std::lower_bound(was, was + n, o);
        same = o >= 0 && at != was + n && *at == o;
        if (same) map[a] = static_cast<int32_t>(at - was);
      }
      if (!same) continue;
      source[c] = src;
      entry_map[c] = std::move(map);
    }
  } else if (cell_model == nullptr && old.cell_model == nullptr && corotational != nullptr &&
             old.corotational != nullptr) {
    // Elements: by kind and rest centroid within the source control cell.
    struct Unit {
      int32_t unit;
      int kind;
      Eigen::Vector3d centre;
      double size;
    };
    auto units_by_cell = [](const Impl& im) {
      std::vector<std::vector<Unit>> out(im.d->control().num_cells());
      const std::vector<int32_t>& to_control = im.d->hierarchy.control_cell;
      int32_t unit = 0;
      for (int kind = 0; kind < 3; ++kind) {
        const models::ElementBlock& block = im.layout->blocks[kind];
        for (int32_t e = 0; e < block.size(); ++e, ++unit) {
          const int32_t* ids = block.element_nodes(e);
          Eigen::Vector3d centre = Eigen::Vector3d::Zero();
          for (int i = 0; i < block.nodes; ++i) centre += im.rest_nodes.row(ids[i]).transpose();
          centre /= block.nodes;
          const models::ElementGroup& g = block.groups[block.group[e]];
          const int32_t cell = to_control.empty() ? block.cell[e] : to_control[block.cell[e]];
          out[cell].push_back({unit, kind, centre, std::cbrt(std::abs(g.shape_volume))});
        }
      }
      return out;
    };
    const std::vector<std::vector<Unit>> now = units_by_cell(*this);
    const std::vector<std::vector<Unit>> was = units_by_cell(old);
    for (int32_t c = 0; c < static_cast<int32_t>(now.size()); ++c) {
      const int32_t src = cell_source[c];
      if (src < 0 || src >= static_cast<int32_t>(was.size())) continue;
      for (const Unit& u : now[c]) {
        // The nearest old element of its kind (ties: the first).
        const Unit* best = nullptr;
        double best_d = INFINITY;
        for (const Unit& o : was[src]) {
          const double dist = (o.centre - u.centre).norm();
          if (o.kind == u.kind && dist < best_d) {
            best = &o;
            best_d = dist;
          }
        }
        if (best != nullptr && best_d < 0.25 * u.size) source[u.unit] = best->unit;
      }
    }
  }
  const int32_t carried = plasticity->CarryFrom(*old.plasticity, source, entry_map);
  if (cell_model != nullptr && old.cell_model != nullptr) {
    plasticity->EstimateChanged(*old.plasticity, *old.cell_model, *cell_model, old.rest_control,
                                rest_control, point_source, cell_source, source);
  }
  return carried;
}

absl::Status Solid::Impl::MakeEnvironment(const Scene& scene, const Solid::Surface& surface) {
  // Grouped by control cell, for the environment's culling.
  const std::vector<int32_t>& to_control = d->hierarchy.control_cell;
  std::vector<int32_t> quad_group(quad_cell.size());
  for (size_t q = 0; q < quad_cell.size(); ++q) {
    quad_group[q] = to_control.empty() ? quad_cell[q] : to_control[quad_cell[q]];
  }
  const contact::SurfaceInput input{&surface_rows, &surface.quads, &quad_group, &surface_rest};
  ASSIGN_OR_RETURN(environment, contact::ObstacleContact::Create(scene.environment(), input));
  return absl::OkStatus();
}

double Solid::Impl::CalibrateEnvironment(double h) {
  if (environment == nullptr) return 0;
  // The solid's mean modulus over its material samples.
  environment->Calibrate(mt, MeanYoung(*layout), h, substeps, settings.max_substeps());
  substeps = std::max(substeps, environment->min_substeps());
  return environment->kappa();
}

absl::Status Solid::Impl::ParseParts(
    std::string_view env, std::string_view clay,
    std::vector<contact::ObstacleContact::Touch>& touches,
    std::optional<material::Plasticity::State>& plastic) const {
  if (environment == nullptr && !env.empty()) {
    return absl::DataLossError("environment contacts for a scene without an environment");
  }
  if (environment != nullptr) {
    ASSIGN_OR_RETURN(touches, environment->ParseState(env));
  }
  // Clay: none in the bytes (no material yielded then), or its state.
  if (clay.empty()) return absl::OkStatus();
  if (cell_model == nullptr && corotational == nullptr) {
    return absl::DataLossError("plastic state for a solid without corotational frames");
  }
  ASSIGN_OR_RETURN(plastic, material::Plasticity::ParseState(clay, d->control().num_cells(),
                                                              PlasticUnits()));
  return absl::OkStatus();
}

void Solid::Impl::InstallParts(std::vector<contact::ObstacleContact::Touch> touches,
                               std::optional<material::Plasticity::State> plastic) {
  if (environment != nullptr) environment->set_touches(std::move(touches));
  if (plastic.has_value()) {
    if (plasticity == nullptr) {
      plasticity = std::make_unique<material::Plasticity>(plastic->laws);
      AttachPlasticity();
    }
    plasticity->set_state(*std::move(plastic));
    return;
  }
  if (plasticity == nullptr) return;
  // A state from before the first clay was painted: elastic again (and no
  // model, the retired one included, keeps a hook into the part).
  plasticity.reset();
  AttachPlasticity();
  {
    std::lock_guard<std::mutex> lock(retired_mu);
    if (retired.has_value() && retired->build.cell_model != nullptr) {
      retired->build.cell_model->set_flow(nullptr);
    }
    if (retired.has_value() && retired->build.corotational != nullptr) {
      retired->build.corotational->set_flow(nullptr);
    }
  }
}

}  // namespace dynsolid::solid
