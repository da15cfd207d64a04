// Building a solid (Create, CreateWith): the scene's regions checked, its
// elements laid out and their material built (solid_material.cc), the
// loads placed, the stable step estimated and the integrator chosen, and
// the solid started at rest.
#include "solver/solid/solid.h"
#include "solver/solid/design.h"
#include "solver/solid/solid_impl.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <functional>
#include <map>
#include <mutex>
#include <numeric>
#include <optional>
#include <type_traits>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include "absl/strings/str_cat.h"
#include "solver/common/build_watch.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"
#include "solver/common/worker_pool.h"
#include "solver/solid/cell_assembly.h"
#include "solver/solid/cell_partials.h"
#include "solver/fem/node_rows.h"
#include "solver/integrators/backward_euler.h"
#include "solver/integrators/central_difference.h"
#include "solver/models/cell_corotation.h"
#include "solver/models/corotational.h"
#include "solver/models/cubic_quadrature.h"
#include "solver/models/element_blocks.h"
#include "solver/models/local_frame.h"
#include "solver/mesh/boundary.h"
#include "solver/models/measure.h"
#include "solver/scene/scene_loader.h"
#include "solver/subdivision/mcj.h"

namespace dynsolid::solid {

int Solid::Impl::SubstepsFor(double omega) const {
  const double stable = omega > 0 ? 2.0 / omega : INFINITY;
  const double limit = settings.stability_safety() * stable;
  // Saturates: a stiffness without bound (a paint of 1e300 Pa) needs more
  // sub-steps than any int, which the callers refuse past max_substeps.
  const double needed = std::ceil(settings.time_step() / limit);
  if (!(needed < static_cast<double>(std::numeric_limits<int>::max()))) {
    return std::numeric_limits<int>::max();
  }
  return std::max(MinSubsteps(), static_cast<int>(needed));
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::Create(const Scene& scene,
                                                     scene::Discretization discretization) {
  return Create(scene, std::move(discretization), 0);
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::Create(const Scene& scene,
                                                     scene::Discretization discretization,
                                                     int threads) {
  return CreateWith(scene, std::move(discretization), threads, nullptr);
}

// CreateWith's phases over the solid being built (a nested class: it reads
// and writes the solid's own members). Each returns the first error of its
// part of the scene, naming the field.
class Solid::Builder {
 public:
  Builder(Solid& s, const Scene& scene)
      : s_(s), im_(*s.impl_), scene_(scene), rep_(s.report_),
        control_(s.d_.control()), nc_(control_.num_vertices()) {}

  // Region indices in range, before anything is made.
  absl::Status CheckRegions() const;
  // The element layout and its material (design, painted regions, a
  // sampler or whole arrays: CreateWith's), installed; clay.
  absl::Status LayMaterial(const models::MaterialSampler* materials, const Solid* carried,
                           const models::ElementMaterials* whole);
  // Penalty springs, loads, constraints, gravity, the environment and the
  // traced points.
  absl::Status PlaceLoads();
  // The stable step, the integrator and the sub-steps.
  absl::Status ChooseStep(bool carried);
  // Rest positions with the scene's initial rigid velocity; the step's
  // buffers and the energy ledger.
  void StartAtRest();

 private:
  Solid& s_;
  Impl& im_;
  const Scene& scene_;
  BuildReport& rep_;
  const mesh::CellComplex& control_;
  const int32_t nc_;
};

absl::Status Solid::Builder::CheckRegions() const {
  for (const Region& r : scene_.constraints().fixed()) {
    for (int32_t c : r.control_cells()) {
      if (c >= control_.num_cells()) {
        return absl::InvalidArgumentError(absl::StrCat("constraints.fixed: control cell ", c,
                                                       " is out of range [0, ",
                                                       control_.num_cells(), ")"));
      }
    }
    for (int32_t v : r.control_points()) {
      if (v >= nc_) {
        return absl::InvalidArgumentError(absl::StrCat(
            "constraints.fixed: control point ", v, " is out of range [0, ", nc_, ")"));
      }
    }
  }
  for (int i = 0; i < scene_.loads().pressures_size(); ++i) {
    RETURN_IF_ERROR(im_.CheckControlCells(scene_.loads().pressures(i).region(),
                                          absl::StrCat("loads.pressures[", i, "].region")));
  }
  return absl::OkStatus();
}

absl::Status Solid::Builder::LayMaterial(const models::MaterialSampler* materials,
                                         const Solid* carried,
                                         const models::ElementMaterials* whole) {
  Solid* s = &s_;
  Impl& im = im_;
  BuildReport& rep = rep_;
  const Points& rest = im.rest_nodes;
  // Materials: base, then painted regions in order.
  const models::MaterialPoint base = ToPoint(scene_.materials().base());
  std::vector<std::pair<const Region*, models::MaterialPoint>> painted;
  for (const MaterialRegion& mr : scene_.materials().regions()) {
    painted.push_back({&mr.region(), ToPoint(mr.material())});
  }
  models::MaterialSampler sampler = [&](const Eigen::Vector3d& x, int32_t cell) {
    models::MaterialPoint m = base;
    for (const auto& [region, material] : painted) {
      if (InRegion(*region, x, cell)) m = material;
    }
    return m;
  };
  // One material throughout (no painted regions, no sampler or arrays
  // given): every point's sample is `base`, so each element takes a whole
  // array of base samples for its kind, the array sampling would make,
  // without a rest position and a sample per quadrature point (block3's
  // scenes; the chair has a painted region and samples).
  std::array<std::vector<models::MaterialPoint>, fem::kElementKinds> base_arrays;
  models::ElementMaterials base_whole;
  // A saved design (scene.design; design.h): its samples, element by
  // element, over what the regions give. Only a plain Create reads it (an
  // edit's build carries its materials over).
  const bool use_design = scene_.has_design() && materials == nullptr && whole == nullptr &&
                          carried == nullptr;
  std::unique_ptr<DesignMaterials> design;
  const Design& saved = scene_.design();
  if (use_design && (saved.elements_size() > 0 || saved.sample_runs_size() > 0 ||
                     saved.materials_size() > 0)) {
    ASSIGN_OR_RETURN(design, DesignMaterials::Make(saved, s->d_.elements, rest));
    base_whole = [&design](int kind, const fem::NodeMatrixX3& x, int32_t) {
      return design->Find(kind, x);
    };
    whole = &base_whole;
  } else if (materials == nullptr && whole == nullptr && painted.empty()) {
    for (int kind = 0; kind < fem::kElementKinds; ++kind) {
      base_arrays[kind].assign(fem::MakeKindTable(static_cast<fem::ElementKind>(kind)).points, base);
    }
    base_whole = [&base_arrays](int kind, const fem::NodeMatrixX3&, int32_t) {
      return &base_arrays[kind];
    };
    whole = &base_whole;
  }
  const auto t_phase = Clock::now();
  auto layout = std::make_unique<models::ElementLayout>(models::BuildElementLayout(
      s->d_.elements, rest, s->d_.hierarchy.control_cell,
      materials != nullptr ? *materials : sampler, whole,
      carried != nullptr ? carried->impl_->layout.get() : nullptr, im.pool.get()));
  if (layout->inverted_elements > 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        layout->inverted_elements, " elements are inverted at rest (det J <= 0 at a quadrature "
        "point); the subdivided mesh is too distorted for finite elements"));
  }
  s->rest_volume_ = layout->rest_volume;
  rep.phases.layout = MsSince(t_phase);
  RETURN_IF_ERROR(common::CheckBuildWatch("element layout"));
  if (carried != nullptr) {
    im.mass_cells = carried->impl_->mass_cells;
    im.k0_cells = carried->impl_->k0_cells;
  }
  // What the build needs only after its material, of the discretization,
  // rest positions and layout alone: made beside the cells' partials, each
  // a part of their pass, on the pool thread that is free first
  // (SumByCells): the element boxes, the boundary surface, and the
  // geometry the fingerprint covers.
  const models::ElementLayout& laid = *layout;
  const std::vector<std::function<void()>> beside = {
      [&] { im.MakeElementBoxes(laid); },
      [&] {
        const auto t0 = Clock::now();
        s->BuildSurface();
        rep.phases.surface = MsSince(t0);
      },
      [&] { im.geometry_key = s->GeometryKey(); }};
  ASSIGN_OR_RETURN(MaterialBuild material, im.BuildMaterial(std::move(layout), false, nullptr, beside));
  rep.phases.model = material.model_ms;
  rep.phases.mass = material.mass_ms;
  rep.control_cell_partials = control_.num_cells();
  rep.mass_cells_made = material.mass_cells != nullptr ? material.mass_cells->made : -1;
  if (material.cell_model != nullptr) rep.k0_cells_made = material.k_cells_made;
  im.InstallMaterial(std::move(material));
  RETURN_IF_ERROR(common::CheckBuildWatch("stiffness model and mass"));
  s->total_mass_ = SumOfValues(im.mt);
  RETURN_IF_ERROR(im.MakePlasticity(scene_));  // clay, when some material yields
  if (use_design) {
    ASSIGN_OR_RETURN(std::optional<material::Plasticity::State> clay,
                     DesignClay(scene_.design(), control_.num_cells(), im.PlasticUnits()));
    if (clay.has_value()) im.InstallParts({}, std::move(clay));
  }
  return absl::OkStatus();
}

absl::Status Solid::Builder::PlaceLoads() {
  Impl& im = im_;
  const Scene& scene = scene_;
  // Penalty springs: the scene's elastic constraints.
  for (const PenaltySpring& spring : scene.constraints().springs()) {
    for (int32_t i = 0; i < nc_; ++i) {
      bool in = InShape(spring.region(), im.rest_control.row(i).transpose());
      for (int32_t c : spring.region().control_cells()) {
        const auto verts = control_.cell_vertices(c);
        in |= std::binary_search(verts.begin(), verts.end(), i);
      }
      if (in && spring.stiffness() > 0) {
        im.spring_point.push_back(i);
        im.spring_k.push_back(spring.stiffness());
      }
    }
  }
  rep_.penalty_springs = static_cast<int32_t>(im.spring_point.size());

  // Loads, with ids: point forces, then pressures, then the scene's fixed
  // regions (held at rest), then gravity.
  LoadSet::Contents loads;
  const bool snap = im.settings.snap_forces_to_quadrature();
  for (int i = 0; i < scene.loads().point_forces_size(); ++i) {
    const PointForce& pf = scene.loads().point_forces(i);
    absl::StatusOr<MaterialLocation> at = im.Locate(V(pf.position()), snap);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("loads.point_forces[", i, "].position: ", at.status().message()));
    }
    loads.point_loads.push_back({loads.next_id++, pf, *at});
  }
  for (int i = 0; i < scene.loads().pressures_size(); ++i) {
    const Pressure& pr = scene.loads().pressures(i);
    std::vector<int32_t> quads = im.SelectQuads(pr.region());
    if (quads.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "loads.pressures[", i, "].region selects no boundary face (no face has its rest "
          "centroid in the region or its cell in control_cells)"));
    }
    loads.pressures.push_back({loads.next_id++, pr, std::move(quads)});
  }
  for (const Region& r : scene.constraints().fixed()) {
    loads.fixes.push_back({loads.next_id++, r, im.SelectControlPoints(r)});
  }
  loads.gravity = V(scene.loads().gravity());
  im.loads = LoadSet(std::move(loads), im.rest_control);
  im.fixed = im.loads.FixedFlags();
  rep_.fixed_control_points = static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  {
    // Loads within physics (load_bounds.h), named by their scene field.
    const LoadScale scale = s_.load_scale();
    RETURN_IF_ERROR(CheckGravity(scale, im.loads.gravity().stableNorm(), "loads.gravity"));
    for (int i = 0; i < scene.loads().point_forces_size(); ++i) {
      RETURN_IF_ERROR(CheckForce(scale, V(scene.loads().point_forces(i).force()).stableNorm(),
                                 absl::StrCat("loads.point_forces[", i, "].force")));
    }
    for (int i = 0; i < scene.loads().pressures_size(); ++i) {
      RETURN_IF_ERROR(CheckPressure(scale, scene.loads().pressures(i).pascals(),
                                    absl::StrCat("loads.pressures[", i, "].pascals")));
    }
  }
  // The environment (floor, obstacles), calibrated below once the sub-step
  // is known.
  RETURN_IF_ERROR(im.MakeEnvironment(scene, s_.surface_));
  im.RebuildConstantLoads();
  im.RebuildPressure();
  rep_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  rep_.gravity = im.loads.has_gravity();

  // Traced points.
  for (int i = 0; i < static_cast<int>(scene.traced_size()); ++i) {
    absl::StatusOr<MaterialLocation> at = im.Locate(V(scene.traced(i).position()), false);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("traced[", i, "] (", scene.traced(i).name(), "): ", at.status().message()));
    }
    im.traced.push_back(*at);
    s_.traced_names_.push_back(scene.traced(i).name());
  }
  return absl::OkStatus();
}

absl::Status Solid::Builder::ChooseStep(bool carried) {
  Impl& im = im_;
  // Stable step and sub-steps.
  auto t_phase = Clock::now();
  im.omega_max = im.EstimateOmegaMax(*im.model, im.mt, im.fixed, &rep_.stable_step_passes,
                                     im.cell_model.get(), im.pool.get());
  im.omega_fixed = im.fixed;
  im.stable_step = im.omega_max > 0 ? 2.0 / im.omega_max : INFINITY;
  rep_.omega_max = im.omega_max;
  rep_.stable_step = im.stable_step;
  im.substeps = im.SubstepsFor(im.omega_max);
  rep_.phases.stable_step = MsSince(t_phase);
  // Implicit steps: asked for, or chosen by `auto` when the explicit scheme
  // would need more than kAutoImplicitSubsteps sub-steps (corotational only).
  constexpr int kAutoImplicitSubsteps = 4;
  im.use_implicit =
      im.settings.integrator() == SolverSettings::BACKWARD_EULER ||
      (im.settings.integrator() == SolverSettings::AUTO && im.corotational != nullptr &&
       im.substeps > kAutoImplicitSubsteps);
  rep_.implicit = im.use_implicit;
  im.ConfigureLinearized();
  s_.ReportMaterial();  // after ConfigureLinearized: the float copies, when made
  if (im.use_implicit) {
    im.substeps = 1;
    im.MakeImplicitOperators();
    t_phase = Clock::now();
    im.k0 = im.StiffnessMatrix(*im.layout, *im.corotational, *im.pool, &im.k0_cells);
    rep_.phases.k0 = MsSince(t_phase);
    RETURN_IF_ERROR(common::CheckBuildWatch("implicit stiffness matrix"));
    // (The per-cell corotation made these partials already: counted there.)
    if (im.cell_model == nullptr) rep_.k0_cells_made = im.k0_cells != nullptr ? im.k0_cells->made : -1;
  }
  rep_.contact_kappa = im.CalibrateEnvironment(s_.h_);  // may raise the sub-steps
  if (!im.use_implicit && im.substeps > im.settings.max_substeps()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.time_step: ", s_.h_, " s needs ", im.substeps,
        " explicit sub-steps (stable step ", rep_.stable_step, " s) but solver.max_substeps is ",
        im.settings.max_substeps(), "; lower the time step or the stiffness"));
  }
  rep_.substeps = im.substeps;
  if (!carried) {
    im.SetSubsteps(im.substeps, s_.h_);
  } else {
    // Built for CarryOver, which sets the integrators up once, for the
    // fixed set the carried pins give (not this scene's, then that one).
    im.h_sub = s_.h_ / im.substeps;
  }
  return absl::OkStatus();
}

void Solid::Builder::StartAtRest() {
  Impl& im = im_;
  const Points& rest = im.rest_nodes;
  // State: rest positions, initial rigid velocity.
  s_.p_ = im.rest_control;
  Eigen::Vector3d centroid = im.rest_control.colwise().mean().transpose();
  const Eigen::Vector3d v0 = V(scene_.initial().linear_velocity());
  const Eigen::Vector3d w0 = V(scene_.initial().angular_velocity());
  s_.p_prev_ = s_.p_;
  for (int32_t i = 0; i < nc_; ++i) {
    if (im.fixed[i]) continue;
    const Eigen::Vector3d x = im.rest_control.row(i).transpose();
    const Eigen::Vector3d v = v0 + w0.cross(x - centroid);
    s_.p_prev_.row(i) = (x - im.h_sub * v).transpose();
  }
  im.nodes.setZero(rest.rows(), 3);
  im.g.setZero(rest.rows(), 3);
  im.f.setZero(nc_, 3);
  im.p_next.setZero(nc_, 3);
  im.backup_p.setZero(nc_, 3);
  im.backup_prev.setZero(nc_, 3);
  im.f_next.setZero(nc_, 3);
  im.velocity = (s_.p_ - s_.p_prev_) / im.h_sub;
  im.mass_velocity = im.mt * im.velocity;
  // The ledger starts from the initial kinetic energy (no strain at rest).
  im.ledger.Start(0.5 * (im.velocity.array() * im.mass_velocity.array()).sum());
}

void Solid::Impl::MakeImplicitOperators() {
  x_nodes.setZero(rest_nodes.rows(), 3);
  kx_nodes.setZero(rest_nodes.rows(), 3);
  Impl* ip = this;
  stiffness_op = [ip](const Points& x, Points& out) {
    if (ip->cell_model != nullptr) {
      ip->cell_model->ApplyLinearized(x, out);
    } else {
      ip->ToNodes(x, ip->x_nodes);
      ip->corotational->ApplyLinearized(ip->x_nodes, ip->kx_nodes);
      ip->FromNodes(ip->kx_nodes, out);
    }
    ++ip->element_passes;
    for (size_t s = 0; s < ip->spring_point.size(); ++s) {
      out.row(ip->spring_point[s]) += ip->spring_k[s] * x.row(ip->spring_point[s]);
    }
  };
  // F - h Kt w = f_ext(p) - A^T g_R(A (p + h w)) - springs at p + h w (the
  // frames of p held: g_R and the springs are affine in the positions);
  // w = v + dv0, the velocity plus the warm start.
  force_ahead = [ip](const Points& v, Points& out) {
    const auto t0 = Clock::now();
    const Points& p = *ip->ahead_from;
    ip->ahead = p + ip->implicit.h() * v;
    if (ip->cell_model != nullptr) {
      ip->ahead_energy = ip->cell_model->AffineForces(ip->ahead, ip->g_ahead);
    } else {
      ip->ToNodes(ip->ahead, ip->x_nodes);
      ip->ahead_energy = ip->corotational->AffineForces(ip->x_nodes, ip->kx_nodes);
      ip->FromNodes(ip->kx_nodes, ip->g_ahead);
    }
    ++ip->element_passes;
    out = ip->f - ip->g_ahead;
    for (size_t s = 0; s < ip->spring_point.size(); ++s) {
      const int32_t i = ip->spring_point[s];
      out.row(i) -= ip->spring_k[s] * (ip->ahead.row(i) - ip->rest_control.row(i));
    }
    ip->ahead_ms = MsSince(t0);
  };
}

absl::StatusOr<std::unique_ptr<Solid>> Solid::CreateWith(
    const Scene& scene, scene::Discretization discretization, int threads,
    const std::function<models::MaterialPoint(const Eigen::Vector3d&, int32_t)>* materials,
    const Solid* carried, const models::ElementMaterials* whole) {
  if (threads < 0 || threads > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("threads: ", threads, " is outside 0-8 (0: the hardware's)"));
  }
  const auto t_build = Clock::now();
  std::unique_ptr<Solid> s(new Solid());
  s->d_ = std::move(discretization);
  s->impl_ = std::make_unique<Impl>();
  Impl& im = *s->impl_;
  im.d = &s->d_;
  im.node_rows = fem::NodeRows(s->d_.node_matrix);
  im.settings = scene::ResolvedSolverSettings(scene);
  im.surface = &s->surface_;
  if (im.settings.integrator() == SolverSettings::BACKWARD_EULER &&
      im.settings.model() != SolverSettings::COROTATIONAL) {
    return absl::UnimplementedError(
        "solver.integrator: backward_euler linearizes the corotational model (docs/model.md 5); "
        "with solver.model local_frame it is not available in this build");
  }
  s->h_ = im.settings.time_step();
  Builder build(*s, scene);
  RETURN_IF_ERROR(build.CheckRegions());
  // Rest configuration.
  im.rest_control = s->d_.control().positions();
  im.rest_nodes = im.node_rows.Multiply(im.rest_control);
  im.pool = std::make_unique<WorkerPool>(threads > 0 ? threads : BuildThreads());
  RETURN_IF_ERROR(build.LayMaterial(materials, carried, whole));
  RETURN_IF_ERROR(build.PlaceLoads());
  RETURN_IF_ERROR(build.ChooseStep(carried != nullptr));
  build.StartAtRest();
  // (A remeshed solid, built here for CarryOver, gets its fingerprint
  // there, from the scene it keeps.)
  if (carried == nullptr) im.fingerprint = s->Fingerprint(scene);
  s->report_.build_ms = MsSince(t_build);
  return s;
}

std::pair<uint64_t, uint64_t> Solid::Fingerprint(const Scene& scene) const {
  Hash128 h;
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    scene.SerializeToCodedStream(&coded);
  }
  h.Bytes(bytes);
  h.Key(impl_->geometry_key);
  return h.value();
}

std::pair<uint64_t, uint64_t> Solid::GeometryKey() const {
  Hash128 h;
  const Impl& im = *impl_;
  h.Doubles(im.rest_control.data(), im.rest_control.size());
  const SparseMatrix& nm = d_.node_matrix;
  h.Mix(nm.rows());
  h.Mix(nm.cols());
  h.Ints(nm.outerIndexPtr(), nm.outerSize() + 1);
  h.Ints(nm.innerIndexPtr(), nm.nonZeros());
  h.Doubles(nm.valuePtr(), nm.nonZeros());
  const fem::ElementSet& e = d_.elements;
  for (const std::vector<int32_t>* nodes : {&e.cubic_nodes, &e.linear_nodes, &e.pyramid_nodes}) {
    h.Mix(nodes->size());
    h.Ints(nodes->data(), nodes->size());
  }
  return h.value();
}

}  // namespace dynsolid::solid
