// The material field: what depends on the material samples (the force
// model, mass and damping assembled onto the control points, the rest
// stiffness), built from a layout off the loop (BuildMaterial) and
// installed on it (InstallMaterial) by a build, a paint or a restore; the
// material the last install replaced kept for an undo (TakeRetired).
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <optional>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "solver/common/build_watch.h"
#include "solver/common/parallel.h"
#include "solver/common/status_macros.h"
#include "solver/common/worker_pool.h"
#include "solver/models/cell_corotation.h"
#include "solver/models/corotational.h"
#include "solver/models/cubic_quadrature.h"
#include "solver/models/element_blocks.h"
#include "solver/models/local_frame.h"
#include "solver/models/measure.h"
#include "solver/solid/cell_assembly.h"
#include "solver/solid/cell_partials.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

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
    // The entries a dense sum keeps: a sum that cancels to zero leaves
    // (so that the pattern does not depend on which way was summed).
    auto nonzero = [](const Eigen::Index&, const Eigen::Index&, const double& v) {
      return !(std::abs(v) <= 0.0);
    };
    mt = sums.sparse[0];
    mt.prune(nonzero);
    if (has_damping) {
      dt = sums.sparse[1];
      dt.prune(nonzero);
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
  // Small control meshes sum densely (up to 32 MiB a matrix).
  const bool dense_mass = nm.cols() <= 2048;
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

// K0 = A^T K A of the corotational model at rest, plus the penalty springs;
// summed cell by cell (cell_assembly.h) with the partials of `previous`.
SparseMatrix Solid::Impl::StiffnessSparse(
    const scene::Discretization& d, const models::ElementLayout& layout,
    const models::CorotationalModel& corotational, const std::vector<int32_t>& spring_point,
    const std::vector<double>& spring_k, WorkerPool& threads, const CellPartials* previous,
    std::shared_ptr<const CellPartials>* next) {
  const SparseMatrix& nm = d.node_matrix;
  CellPoints points(layout, nm, threads.size());
  StiffnessPartials blocks(layout, corotational, points, threads.size());
  const CellSumSpec& spec = blocks.spec();
  // Control meshes are small: sum into a dense matrix unless it would pass
  // 32 MiB.
  const int64_t dofs = 3 * static_cast<int64_t>(nm.cols());
  const bool dense = dofs <= 2048;
  CellSums sums;
  std::shared_ptr<const CellPartials> made =
      SumByCell(nm, layout, d.hierarchy.control_cell, d.control().num_cells(), spec, previous,
                threads, dense, sums);
  if (next != nullptr) *next = made->bytes <= kMaxCarriedBytes ? made : nullptr;
  SparseMatrix k = dense ? SparseOf(sums.matrices[0]) : std::move(sums.sparse[0]);
  // The springs after the cells (a diagonal entry the cells left out is
  // inserted: the sparse matrix is then uncompressed until the end).
  for (size_t s = 0; s < spring_point.size(); ++s) {
    for (int c = 0; c < 3; ++c) k.coeffRef(3 * spring_point[s] + c, 3 * spring_point[s] + c) += spring_k[s];
  }
  k.makeCompressed();
  return k;
}

std::vector<Eigen::Triplet<double, int32_t>> Solid::Impl::TripletsOf(const SparseMatrix& k) {
  std::vector<Eigen::Triplet<double, int32_t>> t;
  t.reserve(static_cast<size_t>(k.nonZeros()));
  for (int32_t r = 0; r < k.outerSize(); ++r) {
    for (SparseMatrix::InnerIterator it(k, r); it; ++it) t.emplace_back(r, static_cast<int32_t>(it.col()), it.value());
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

}  // namespace dynsolid::solid
