// Building a solid: the scene's mesh subdivided, its elements laid out and
// grouped by rest shape, the force model, mass and damping assembled onto
// the control points, the stable step estimated (Create, CreateWith), and a
// material layout built off the loop and installed (BuildMaterial,
// InstallMaterial) as paints and topology edits need.
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

namespace {

// The nonzero entries of a dense square matrix as a row-major sparse one
// (what sparseView(0, 0) keeps), written row by row into their arrays.
SparseMatrix SparseOf(const Eigen::MatrixXd& m) {
  const Eigen::Index n = m.rows();
  std::vector<int32_t> outer{0}, inner;
  std::vector<double> values;
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      const double v = m(i, j);
      if (!(std::abs(v) <= 0.0)) {
        inner.push_back(static_cast<int32_t>(j));
        values.push_back(v);
      }
    }
    outer.push_back(static_cast<int32_t>(inner.size()));
  }
  return subdivision::FromCsr(static_cast<int32_t>(n), static_cast<int32_t>(m.cols()), outer,
                              inner, values);
}

}  // namespace

// Mt and Dt from their cell sums (cell_assembly.h, cell_partials.h).
void Solid::Impl::ControlMatricesFrom(const CellSums& sums, bool dense, bool has_damping,
                                      SparseMatrix& mt, SparseMatrix& dt) const {
  const int32_t nc = static_cast<int32_t>(d->node_matrix.cols());
  if (dense) {
    mt = SparseOf(sums.matrices[0]);
    if (has_damping) dt = SparseOf(sums.matrices[1]);
  } else {
    mt.resize(nc, nc);
    mt.setFromTriplets(sums.triplets[0].begin(), sums.triplets[0].end());
    if (has_damping) {
      dt.resize(nc, nc);
      dt.setFromTriplets(sums.triplets[1].begin(), sums.triplets[1].end());
    }
  }
  mt.makeCompressed();
  if (has_damping) dt.makeCompressed();
  if (settings.mass() == SolverSettings::LUMPED) {
    // Row sums on the diagonal: the same total (and each control point's
    // share of it), summed in row order.
    auto lump = [nc](SparseMatrix& m) {
      const Eigen::VectorXd rows = m * Eigen::VectorXd::Ones(nc);
      SparseMatrix d(nc, nc);
      d.reserve(Eigen::VectorXi::Ones(nc));
      for (int32_t i = 0; i < nc; ++i) d.insert(i, i) = rows[i];
      d.makeCompressed();
      m = std::move(d);
    };
    lump(mt);
    if (has_damping) lump(dt);
  }
}

bool Solid::Impl::SameMassAndDamping(const models::ElementLayout& l) const {
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& now = layout->blocks[kind];
    const models::ElementBlock& next = l.blocks[kind];
    if (now.size() != next.size()) return false;
    for (int32_t e = 0; e < next.size(); ++e) {
      const auto& a = layout->materials[now.groups[now.group[e]].material];
      const auto& b = l.materials[next.groups[next.group[e]].material];
      if (a.size() != b.size()) return false;
      for (size_t q = 0; q < a.size(); ++q) {
        if (a[q].density != b[q].density || a[q].damping != b[q].damping) return false;
      }
    }
  }
  return true;
}

namespace {
std::atomic<double> g_max_element_bytes{Solid::kMaxSharedMatrixBytes};
}  // namespace

void Solid::SetMaxElementBytesForTesting(double bytes) {
  g_max_element_bytes.store(bytes > 0 ? bytes : kMaxSharedMatrixBytes);
}

absl::StatusOr<MaterialBuild> Solid::Impl::BuildMaterial(
    std::unique_ptr<models::ElementLayout> l, bool reuse, WorkerPool* model_pool,
    const std::vector<std::function<void()>>& beside) const {
  reuse = reuse && paint_reuse && model != nullptr && layout != nullptr;
  WorkerPool& threads = model_pool != nullptr ? *model_pool : *pool;
  MaterialBuild b;
  for (const auto& array : l->materials) {
    for (const auto& m : array) b.has_damping |= m.damping > 0;
  }
  // The model the scene asks for, after checking what its element
  // matrices would take: curved meshes share few of them. Cubic elements
  // applied at their quadrature points (every one in the corotational
  // model, those of small groups in the local-frame one) keep 11 numbers
  // per point instead (models/cubic_quadrature.h). A solid corotated per
  // control cell makes no element matrices (CorotationalModel::Products).
  const auto t_model = Clock::now();
  const bool corot = settings.model() == SolverSettings::COROTATIONAL;
  const bool per_cell = corot && settings.corotation() == SolverSettings::CONTROL_CELL;
  double bytes = 0;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = l->blocks[kind];
    const double n = block.nodes;
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      const int32_t members = block.group_start[gi + 1] - block.group_start[gi];
      if (kind == 0 && (corot || members <= models::kQuadratureGroupSize)) {
        bytes += members * 64.0 * models::kFactorsPerPoint * 8.0;
      } else {
        bytes += (corot ? 9.0 : 3.0) * n * n * 8.0;
      }
    }
  }
  const double limit = g_max_element_bytes.load();
  if (!per_cell && bytes > limit) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "the ", corot ? "corotational" : "local-frame", " element data of this scene would take ",
        static_cast<int64_t>(bytes / 1048576.0), " MiB (", l->blocks[0].groups.size(),
        " distinct cubic elements), above the limit of ",
        static_cast<int64_t>(limit / 1048576.0),
        " MiB; use fewer subdivision levels or a more regular control mesh"));
  }
  if (corot) {
    // Corotated per control cell, the solid steps in control space and
    // never asks this model for its element products.
    auto m = std::make_unique<models::CorotationalModel>(
        *l, rest_nodes, threads, reuse ? corotational : nullptr, models::kEveryGroup,
        per_cell ? models::CorotationalModel::Products::kWhenUsed
                 : models::CorotationalModel::Products::kNow);
    b.corotational = m.get();
    b.shared_matrix_bytes = m->shared_matrix_bytes();
    b.element_bytes = m->per_element_bytes();
    b.model = std::move(m);
  } else {
    // One measure part per thread: its sums do not depend on the split.
    const auto* previous =
        reuse ? dynamic_cast<const models::LocalFrameModel*>(model.get()) : nullptr;
    models::DeformationMeasure measure =
        previous != nullptr
            ? previous->measure()
            : models::DeformationMeasure(d->fine(), d->elements, rest_nodes, pool->size());
    auto m = std::make_unique<models::LocalFrameModel>(
        *l, std::move(measure), d->elements.num_nodes(), threads, previous,
        settings.element_products() == SolverSettings::FLOAT);
    b.shared_matrix_bytes = m->shared_matrix_bytes();
    b.element_bytes = m->per_element_bytes();
    b.model = std::move(m);
  }
  // The cells' partials of the per-cell corotation (K0) and of the mass
  // (cell_assembly.h, cell_partials.h), made in one pass over the cells
  // that share what they read of each cell (CellPoints); a cell whose key
  // the previous build has is taken from it. The cells' supports and keys
  // are those of this solid's discretization when it has them.
  CellGeometry geometry;
  if (reuse && cell_geometry != nullptr) geometry = *cell_geometry;
  const SparseMatrix& nm = d->node_matrix;
  const bool make_mass = !(reuse && SameMassAndDamping(*l));
  const bool dense_mass = nm.cols() <= 6000;  // small control meshes sum densely
  CellPoints points(*l, nm, threads.size());
  std::optional<StiffnessPartials> stiffness;
  std::optional<MassPartials> mass;
  CellSums k_sums, m_sums;
  std::vector<CellSumJob> jobs;
  if (per_cell) {
    stiffness.emplace(*l, *b.corotational, points, threads.size());
    stiffness->spec().per_cell = true;
    stiffness->spec().geometry = &geometry;
    jobs.push_back({&stiffness->spec(), k0_cells.get(), false, &k_sums, nullptr});
  }
  if (make_mass) {
    mass.emplace(*l, b.has_damping, points, threads.size());
    mass->spec().geometry = &geometry;
    jobs.push_back({&mass->spec(), mass_cells.get(), dense_mass, &m_sums, nullptr});
  }
  if (!jobs.empty()) {
    SumByCells(nm, *l, d->hierarchy.control_cell, d->control().num_cells(), jobs, threads, beside);
  } else {
    for (const std::function<void()>& job : beside) job();
  }
  if (per_cell) {
    const std::shared_ptr<const CellPartials> made = jobs[0].made;
    b.cell_model = CellCorotationFrom(k_sums, threads);
    b.k_cells_made = made->made;
    b.k_cells = made->bytes <= kMaxCarriedBytes ? made : nullptr;
  }
  b.model_ms = MsSince(t_model);
  // Mass (and damping) in control-point space.
  const auto t_mass = Clock::now();
  if (!make_mass) {
    b.mt = mt;
    b.dt = dt;
    b.mass_cells = mass_cells;
  } else {
    ControlMatricesFrom(m_sums, dense_mass, b.has_damping, b.mt, b.dt);
    const std::shared_ptr<const CellPartials> made = jobs.back().made;
    b.mass_cells = made->bytes <= kMaxCarriedBytes ? made : nullptr;
  }
  b.mass_ms = MsSince(t_mass);
  if (static_cast<int32_t>(geometry.keys.size()) == d->control().num_cells()) {
    b.geometry = std::make_shared<const CellGeometry>(std::move(geometry));
  }
  b.layout = std::move(l);
  return b;
}

void Solid::Impl::InstallMaterial(MaterialBuild b) {
  if (layout != nullptr && model != nullptr) {
    RetiredMaterial r;
    r.build.layout = layout;
    r.build.model = model;
    r.build.corotational = corotational;
    r.build.cell_model = cell_model;
    r.build.k_cells = cell_model != nullptr ? k0_cells : nullptr;
    r.build.mt = mt;
    r.build.dt = dt;
    r.build.mass_cells = mass_cells;
    r.build.has_damping = has_damping;
    r.k0 = std::move(k0);  // the caller installs the new one (implicit)
    r.k0_cells = k0_cells;
    std::lock_guard<std::mutex> lock(retired_mu);
    retired = std::move(r);
  }
  ++material_epoch;
  gravity_mass.resize(0);  // per material
  // The old model references the old layout: replace the model first.
  model = std::move(b.model);
  corotational = b.corotational;
  cell_model = std::move(b.cell_model);
  if (cell_model != nullptr) {
    cell_model->set_pool(*pool);
    k0_cells = std::move(b.k_cells);
  }
  layout = std::move(b.layout);
  mt = std::move(b.mt);
  dt = std::move(b.dt);
  mass_cells = std::move(b.mass_cells);
  if (b.geometry != nullptr) cell_geometry = std::move(b.geometry);
  has_damping = b.has_damping;
  ++contact.epoch;  // the contact stiffness depends on the material
  AttachPlasticity();
  ConfigureLinearized();
}

std::optional<Solid::Impl::RetiredMaterial> Solid::Impl::TakeRetired(
    const std::function<bool(const models::ElementLayout&)>& is_it) const {
  std::lock_guard<std::mutex> lock(retired_mu);
  if (!retired.has_value() || !is_it(*retired->build.layout)) return std::nullopt;
  std::optional<RetiredMaterial> out = std::move(retired);
  retired.reset();
  return out;
}

std::unique_ptr<models::InternalForceModel> Solid::Impl::ModelCopy(
    const models::ElementLayout& l, const models::InternalForceModel& live,
    WorkerPool& threads) const {
  if (const auto* corot = dynamic_cast<const models::CorotationalModel*>(&live)) {
    return std::make_unique<models::CorotationalModel>(
        l, rest_nodes, threads, corot, models::kEveryGroup,
        corot->has_products() ? models::CorotationalModel::Products::kNow
                              : models::CorotationalModel::Products::kWhenUsed);
  }
  const auto& lf = static_cast<const models::LocalFrameModel&>(live);
  return std::make_unique<models::LocalFrameModel>(
      l, lf.measure(), d->elements.num_nodes(), threads, &lf,
      settings.element_products() == SolverSettings::FLOAT);
}

bool Solid::Impl::SinglePrecisionLinearized() const {
  return use_implicit && !double_cg && settings.cg_tolerance() >= kSinglePrecisionCgTolerance;
}

void Solid::Impl::ConfigureLinearized() {
  if (corotational == nullptr) return;
  corotational->SetSinglePrecisionLinearized(SinglePrecisionLinearized());
}

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
  const mesh::CellComplex& control = s->d_.control();
  const int32_t nc = control.num_vertices();
  for (const Region& r : scene.constraints().fixed()) {
    for (int32_t c : r.control_cells()) {
      if (c >= control.num_cells()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "constraints.fixed: control cell ", c, " is out of range [0, ", control.num_cells(), ")"));
      }
    }
    for (int32_t v : r.control_points()) {
      if (v >= nc) {
        return absl::InvalidArgumentError(absl::StrCat(
            "constraints.fixed: control point ", v, " is out of range [0, ", nc, ")"));
      }
    }
  }
  for (int i = 0; i < scene.loads().pressures_size(); ++i) {
    RETURN_IF_ERROR(im.CheckControlCells(scene.loads().pressures(i).region(),
                                         absl::StrCat("loads.pressures[", i, "].region")));
  }

  // Rest configuration.
  im.rest_control = control.positions();
  im.rest_nodes = im.node_rows.Multiply(im.rest_control);
  const Points& rest = im.rest_nodes;
  im.pool = std::make_unique<WorkerPool>(threads > 0 ? threads : BuildThreads());
  BuildReport& rep = s->report_;

  // Materials: base, then painted regions in order.
  const models::MaterialPoint base = ToPoint(scene.materials().base());
  std::vector<std::pair<const Region*, models::MaterialPoint>> painted;
  for (const MaterialRegion& mr : scene.materials().regions()) {
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
  std::array<std::vector<models::MaterialPoint>, 3> base_arrays;
  models::ElementMaterials base_whole;
  // A saved design (scene.design; design.h): its samples, element by
  // element, over what the regions give. Only a plain Create reads it (an
  // edit's build carries its materials over).
  const bool use_design = scene.has_design() && materials == nullptr && whole == nullptr &&
                          carried == nullptr;
  std::unique_ptr<DesignMaterials> design;
  const Design& saved = scene.design();
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
  auto t_phase = Clock::now();
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
  rep.control_cell_partials = control.num_cells();
  rep.mass_cells_made = material.mass_cells != nullptr ? material.mass_cells->made : -1;
  if (material.cell_model != nullptr) rep.k0_cells_made = material.k_cells_made;
  im.InstallMaterial(std::move(material));
  RETURN_IF_ERROR(common::CheckBuildWatch("stiffness model and mass"));
  s->total_mass_ = SumOfValues(im.mt);
  RETURN_IF_ERROR(im.MakePlasticity(scene));  // clay, when some material yields
  if (use_design) {
    ASSIGN_OR_RETURN(std::optional<material::Plasticity::State> clay,
                     DesignClay(scene.design(), control.num_cells(), im.PlasticUnits()));
    if (clay.has_value()) im.InstallParts({}, std::move(clay));
  }

  // Penalty springs: the scene's elastic constraints.
  for (const PenaltySpring& spring : scene.constraints().springs()) {
    for (int32_t i = 0; i < nc; ++i) {
      bool in = InShape(spring.region(), im.rest_control.row(i).transpose());
      for (int32_t c : spring.region().control_cells()) {
        const auto verts = control.cell_vertices(c);
        in |= std::binary_search(verts.begin(), verts.end(), i);
      }
      if (in && spring.stiffness() > 0) {
        im.spring_point.push_back(i);
        im.spring_k.push_back(spring.stiffness());
      }
    }
  }
  rep.penalty_springs = static_cast<int32_t>(im.spring_point.size());

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
  rep.fixed_control_points = static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  {
    // Loads within physics (load_bounds.h), named by their scene field.
    const LoadScale scale = s->load_scale();
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
  RETURN_IF_ERROR(im.MakeEnvironment(scene, s->surface_));
  im.RebuildConstantLoads();
  im.RebuildPressure();
  rep.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  rep.gravity = im.loads.has_gravity();

  // Traced points.
  for (int i = 0; i < static_cast<int>(scene.traced_size()); ++i) {
    absl::StatusOr<MaterialLocation> at = im.Locate(V(scene.traced(i).position()), false);
    if (!at.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("traced[", i, "] (", scene.traced(i).name(), "): ", at.status().message()));
    }
    im.traced.push_back(*at);
    s->traced_names_.push_back(scene.traced(i).name());
  }

  // Stable step and sub-steps.
  t_phase = Clock::now();
  im.omega_max = im.EstimateOmegaMax(*im.model, im.mt, im.fixed, &rep.stable_step_passes,
                                     im.cell_model.get(), im.pool.get());
  im.omega_fixed = im.fixed;
  im.stable_step = im.omega_max > 0 ? 2.0 / im.omega_max : INFINITY;
  rep.omega_max = im.omega_max;
  rep.stable_step = im.stable_step;
  im.substeps = im.SubstepsFor(im.omega_max);
  rep.phases.stable_step = MsSince(t_phase);
  // Implicit steps: asked for, or chosen by `auto` when the explicit scheme
  // would need more than kAutoImplicitSubsteps sub-steps (corotational only).
  constexpr int kAutoImplicitSubsteps = 4;
  im.use_implicit =
      im.settings.integrator() == SolverSettings::BACKWARD_EULER ||
      (im.settings.integrator() == SolverSettings::AUTO && im.corotational != nullptr &&
       im.substeps > kAutoImplicitSubsteps);
  rep.implicit = im.use_implicit;
  im.ConfigureLinearized();
  s->ReportMaterial();  // after ConfigureLinearized: the float copies, when made
  if (im.use_implicit) {
    im.substeps = 1;
    im.x_nodes.setZero(rest.rows(), 3);
    im.kx_nodes.setZero(rest.rows(), 3);
    Impl* ip = &im;
    im.stiffness_op = [ip](const Points& x, Points& out) {
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
    im.force_ahead = [ip](const Points& v, Points& out) {
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
  if (im.use_implicit) {
    t_phase = Clock::now();
    im.k0 = im.StiffnessMatrix(*im.layout, *im.corotational, *im.pool, &im.k0_cells);
    rep.phases.k0 = MsSince(t_phase);
    RETURN_IF_ERROR(common::CheckBuildWatch("implicit stiffness matrix"));
    // (The per-cell corotation made these partials already: counted there.)
    if (im.cell_model == nullptr) rep.k0_cells_made = im.k0_cells != nullptr ? im.k0_cells->made : -1;
  }
  rep.contact_kappa = im.CalibrateEnvironment(s->h_);  // may raise the sub-steps
  if (!im.use_implicit && im.substeps > im.settings.max_substeps()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solver.time_step: ", s->h_, " s needs ", im.substeps,
        " explicit sub-steps (stable step ", rep.stable_step, " s) but solver.max_substeps is ",
        im.settings.max_substeps(), "; lower the time step or the stiffness"));
  }
  rep.substeps = im.substeps;
  if (carried == nullptr) {
    im.SetSubsteps(im.substeps, s->h_);
  } else {
    // Built for CarryOver, which sets the integrators up once, for the
    // fixed set the carried pins give (not this scene's, then that one).
    im.h_sub = s->h_ / im.substeps;
  }

  // State: rest positions, initial rigid velocity.
  s->p_ = im.rest_control;
  Eigen::Vector3d centroid = im.rest_control.colwise().mean().transpose();
  const Eigen::Vector3d v0 = V(scene.initial().linear_velocity());
  const Eigen::Vector3d w0 = V(scene.initial().angular_velocity());
  s->p_prev_ = s->p_;
  for (int32_t i = 0; i < nc; ++i) {
    if (im.fixed[i]) continue;
    const Eigen::Vector3d x = im.rest_control.row(i).transpose();
    const Eigen::Vector3d v = v0 + w0.cross(x - centroid);
    s->p_prev_.row(i) = (x - im.h_sub * v).transpose();
  }
  im.nodes.setZero(rest.rows(), 3);
  im.g.setZero(rest.rows(), 3);
  im.f.setZero(nc, 3);
  im.p_next.setZero(nc, 3);
  im.backup_p.setZero(nc, 3);
  im.backup_prev.setZero(nc, 3);
  im.f_next.setZero(nc, 3);
  im.velocity = (s->p_ - s->p_prev_) / im.h_sub;
  im.mass_velocity = im.mt * im.velocity;
  // The ledger starts from the initial kinetic energy (no strain at rest).
  im.ledger.started = true;
  im.ledger.h_min = 0.5 * (im.velocity.array() * im.mass_velocity.array()).sum();
  im.ledger.peak = im.ledger.h_min;
  // (A remeshed solid, built here for CarryOver, gets its fingerprint
  // there, from the scene it keeps.)
  if (carried == nullptr) im.fingerprint = s->Fingerprint(scene);
  rep.build_ms = MsSince(t_build);
  return s;
}

std::unique_ptr<models::CellCorotation> Solid::Impl::CellCorotationFrom(CellSums& sums,
                                                                       WorkerPool& threads) const {
  std::vector<models::CellCorotation::Cell> cells(sums.supports.size());
  // One matrix per distinct partial (cells of one key share it).
  std::map<const std::vector<Eigen::MatrixXd>*, std::shared_ptr<const Eigen::MatrixXd>> matrix;
  for (size_t c = 0; c < cells.size(); ++c) {
    const Eigen::MatrixXd& g = (*sums.partials[c])[1];  // the cell's g_j (StiffnessPartials)
    cells[c].gradient.resize(g.rows());
    for (Eigen::Index a = 0; a < g.rows(); ++a) cells[c].gradient[a] = g.row(a).transpose();
    cells[c].support = std::move(sums.supports[c]);
    const auto& partial = sums.partials[c];
    auto [it, fresh] = matrix.try_emplace(partial.get());
    if (fresh) it->second = std::shared_ptr<const Eigen::MatrixXd>(partial, &(*partial)[0]);
    cells[c].k = it->second;
  }
  return std::make_unique<models::CellCorotation>(std::move(cells), rest_control, threads);
}

// K0 = A^T K A of the corotational model at rest, plus the penalty springs,
// as triplets; summed cell by cell (cell_assembly.h) with the partials of
// `previous`.
std::vector<Eigen::Triplet<double, int32_t>> Solid::Impl::StiffnessTriplets(
    const scene::Discretization& d, const models::ElementLayout& layout,
    const models::CorotationalModel& corotational, const std::vector<int32_t>& spring_point,
    const std::vector<double>& spring_k, WorkerPool& threads, const CellPartials* previous,
    std::shared_ptr<const CellPartials>* next) {
  const SparseMatrix& nm = d.node_matrix;
  CellPoints points(layout, nm, threads.size());
  StiffnessPartials blocks(layout, corotational, points, threads.size());
  const CellSumSpec& spec = blocks.spec();
  // Control meshes are small: sum into a dense matrix (no triplet per
  // element entry) unless it would pass 32 MiB.
  const int64_t dofs = 3 * static_cast<int64_t>(nm.cols());
  const bool dense = dofs <= 2048;
  CellSums sums;
  std::shared_ptr<const CellPartials> made =
      SumByCell(nm, layout, d.hierarchy.control_cell, d.control().num_cells(), spec, previous,
                threads, dense, sums);
  if (next != nullptr) *next = made->bytes <= kMaxCarriedBytes ? made : nullptr;
  std::vector<Eigen::Triplet<double, int32_t>> t;
  if (dense) {
    const Eigen::MatrixXd& sum = sums.matrices[0];
    for (int64_t c = 0; c < dofs; ++c)
      for (int64_t r = 0; r < dofs; ++r) {
        if (sum(r, c) != 0) t.emplace_back(static_cast<int32_t>(r), static_cast<int32_t>(c), sum(r, c));
      }
  } else {
    t = std::move(sums.triplets[0]);
  }
  for (size_t k = 0; k < spring_point.size(); ++k) {
    for (int c = 0; c < 3; ++c) {
      t.emplace_back(3 * spring_point[k] + c, 3 * spring_point[k] + c, spring_k[k]);
    }
  }
  return t;
}

void Solid::ReportMaterial() {
  const Impl& im = *impl_;
  report_.cubic_groups = static_cast<int32_t>(im.layout->blocks[0].groups.size());
  report_.linear_groups = static_cast<int32_t>(im.layout->blocks[1].groups.size());
  report_.pyramid_groups = static_cast<int32_t>(im.layout->blocks[2].groups.size());
  report_.material_arrays = static_cast<int32_t>(im.layout->materials.size());
  report_.damping_matrix = im.has_damping;
  report_.node_matrix_bytes = im.node_rows.bytes();
  report_.node_matrix_float_values = im.node_rows.float_values();
  // Filled by the model; BuildMaterial read them.
  if (im.corotational != nullptr) {
    report_.single_precision_cg = im.corotational->single_precision_linearized();
    report_.shared_matrix_bytes = im.corotational->shared_matrix_bytes();
    report_.element_bytes = im.corotational->per_element_bytes();
    report_.quadrature_elements = im.corotational->quadrature_elements();
    report_.measure_quad_path.clear();
    report_.corotated_cells = im.cell_model != nullptr ? im.cell_model->cells() : 0;
    report_.cell_matrices = im.cell_model != nullptr ? im.cell_model->distinct_matrices() : 0;
    report_.cell_matrix_bytes = im.cell_model != nullptr ? im.cell_model->matrix_bytes() : 0;
  } else {
    const auto* lf = static_cast<const models::LocalFrameModel*>(im.model.get());
    report_.shared_matrix_bytes = lf->shared_matrix_bytes();
    report_.element_bytes = lf->per_element_bytes();
    report_.factorized_elements = lf->factorized_elements();
    report_.quadrature_elements = lf->quadrature_elements();
    report_.measure_quad_path = models::QuadPathName(lf->measure().quad_path());
  }
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
