#include "solver/material/plasticity.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <Eigen/QR>

#include "absl/strings/str_cat.h"

namespace dynsolid::material {
namespace {

constexpr char kStateMagic[4] = {'P', 'L', 'S', '1'};

template <typename T>
void Put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

void PutDoubles(std::string& out, const std::vector<double>& v) {
  Put<uint64_t>(out, v.size());
  out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(double));
}

class Reader {
 public:
  explicit Reader(std::string_view b) : b_(b) {}
  template <typename T>
  bool Get(T& v) {
    if (b_.size() - pos_ < sizeof(T)) return false;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  bool Doubles(std::vector<double>& v, uint64_t expected) {
    uint64_t n = 0;
    if (!Get(n) || n != expected || (b_.size() - pos_) / sizeof(double) < n) return false;
    v.resize(n);
    if (n > 0) std::memcpy(v.data(), b_.data() + pos_, n * sizeof(double));
    pos_ += n * sizeof(double);
    for (double x : v) {
      if (!std::isfinite(x)) return false;
    }
    return true;
  }
  bool at_end() const { return pos_ == b_.size(); }

 private:
  std::string_view b_;
  size_t pos_ = 0;
};

// u(x) = u0 + A (x - x0), the affine map closest to samples (x_i, u_i) in
// least squares; with too few points, or points on a plane or a line, the
// least-norm A (a translation when A cannot be told).
struct AffineFit {
  Eigen::Vector3d x0 = Eigen::Vector3d::Zero(), u0 = Eigen::Vector3d::Zero();
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d At(const Eigen::Vector3d& x) const { return u0 + a * (x - x0); }
};

AffineFit FitAffine(const std::vector<Eigen::Vector3d>& x, const std::vector<Eigen::Vector3d>& u) {
  AffineFit f;
  const int n = static_cast<int>(x.size());
  if (n == 0) return f;
  for (int i = 0; i < n; ++i) {
    f.x0 += x[i];
    f.u0 += u[i];
  }
  f.x0 /= n;
  f.u0 /= n;
  if (n < 4) return f;
  Eigen::MatrixXd xs(n, 3), us(n, 3);
  for (int i = 0; i < n; ++i) {
    xs.row(i) = (x[i] - f.x0).transpose();
    us.row(i) = (u[i] - f.u0).transpose();
  }
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(xs);
  cod.setThreshold(1e-9);
  f.a = cod.solve(us).transpose();
  return f;
}

}  // namespace

FlowLaw FlowLawOf(const Material& m) {
  FlowLaw law;
  law.yield = m.yield_strain();
  law.rate = m.flow_rate();
  law.hardening = m.hardening();
  law.poisson = m.poisson_ratio();
  return law;
}

Plasticity::Plasticity(std::vector<FlowLaw> laws) : laws_(std::move(laws)) {}

void Plasticity::UpdateActive() {
  const size_t units = first_.size();
  active_.assign(units, 0);
  for (size_t u = 0; u < units; ++u) {
    bool moved = alpha_[u] > 0;
    if (!moved && !offsets_.empty()) {
      const double* up = offsets_.data() + 3 * static_cast<int64_t>(first_[u]);
      for (int e = 0; e < 3 * size_[u] && !moved; ++e) moved = up[e] != 0;
    }
    active_[u] = laws_[unit_cell_[u]].yield > 0 || moved;
  }
}

void Plasticity::SizeUnits(int64_t entries) {
  const size_t units = first_.size();
  entries_ = entries;
  if (alpha_.size() != units || offsets_.size() != static_cast<size_t>(3 * entries)) {
    offsets_.assign(3 * entries, 0.0);
    alpha_.assign(units, 0.0);
    dissipation_.assign(units, 0.0);
  }
  UpdateActive();
}

bool Plasticity::any_yields() const {
  return std::any_of(laws_.begin(), laws_.end(), [](const FlowLaw& l) { return l.yield > 0; });
}

Plasticity::Units Plasticity::UnitsOf(const models::CellCorotation& model) {
  return {model.cells(), model.support_entries()};
}

Plasticity::Units Plasticity::UnitsOf(const models::ElementLayout& layout) {
  Units out;
  for (const models::ElementBlock& block : layout.blocks) {
    out.units += block.size();
    out.entries += static_cast<int64_t>(block.size()) * block.nodes;
  }
  return out;
}

void Plasticity::Attach(models::CellCorotation& model) {
  const int32_t cells = model.cells();
  first_.resize(cells);
  size_.resize(cells);
  unit_cell_.resize(cells);
  scale_.assign(cells, 0.0);
  base_ = {0, 0, 0};
  std::vector<double> u;
  for (int32_t c = 0; c < cells; ++c) {
    first_[c] = model.support_first(c);
    size_[c] = model.support_size(c);
    unit_cell_[c] = c;
    // Twice the energy of a unit uniaxial stress along each axis, averaged.
    const double* x = model.rest_local(c);
    const double nu = laws_[c].poisson;
    u.assign(3 * static_cast<size_t>(size_[c]), 0.0);
    double sum = 0;
    for (int axis = 0; axis < 3; ++axis) {
      for (int a = 0; a < size_[c]; ++a) {
        for (int k = 0; k < 3; ++k) u[3 * a + k] = (k == axis ? 1.0 : -nu) * x[3 * a + k];
      }
      sum += 2.0 * model.Energy(c, u.data());
    }
    scale_[c] = sum / 3.0;
  }
  SizeUnits(model.support_entries());
  model.set_flow(this);
}

void Plasticity::Attach(models::CorotationalModel& model,
                        const std::vector<int32_t>& control_cell) {
  const models::ElementLayout& layout = model.layout();
  const Units units = UnitsOf(layout);
  first_.resize(units.units);
  size_.resize(units.units);
  unit_cell_.resize(units.units);
  scale_.assign(units.units, 0.0);
  int32_t unit = 0;
  int64_t entry = 0;
  for (int kind = 0; kind < 3; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    base_[kind] = unit;
    for (int32_t e = 0; e < block.size(); ++e, ++unit) {
      first_[unit] = static_cast<int32_t>(entry);
      size_[unit] = block.nodes;
      entry += block.nodes;
      const int32_t cell = block.cell[e];
      unit_cell_[unit] = control_cell.empty() ? cell : control_cell[cell];
      // E V: the group's mean sampled modulus times its rest volume.
      const models::ElementGroup& g = block.groups[block.group[e]];
      const std::vector<models::MaterialPoint>& samples = layout.materials[g.material];
      double young = 0;
      for (const models::MaterialPoint& m : samples) young += m.young;
      if (!samples.empty()) young /= static_cast<double>(samples.size());
      scale_[unit] = young * std::abs(g.shape_volume);
    }
  }
  SizeUnits(units.entries);
  model.set_flow(this);
}

void Plasticity::FlowUnit(int32_t unit, const double* u, const double* ku) {
  const FlowLaw& law = laws_[unit_cell_[unit]];
  if (!(law.yield > 0) || !(scale_[unit] > 0)) return;
  const int n = 3 * size_[unit];
  double twice_w = 0;
  for (int e = 0; e < n; ++e) twice_w += u[e] * ku[e];
  if (!(twice_w > 0)) return;
  const double eps = std::sqrt(twice_w / scale_[unit]);
  const double y = law.yield + law.hardening * alpha_[unit];
  if (!(eps > y)) return;
  // The return to the yield surface with linear hardening: eps - d = y +
  // hardening d for the plastic strain increment d = lambda eps, all of it
  // when the rate and step allow, else the fraction rate * dt.
  const double lambda = (1.0 - y / eps) / (1.0 + law.hardening) * std::min(1.0, law.rate * dt_);
  double* up = offsets_.data() + 3 * static_cast<int64_t>(first_[unit]);
  for (int e = 0; e < n; ++e) up[e] += lambda * u[e];
  alpha_[unit] += lambda * eps;
  dissipation_[unit] += lambda * twice_w;
}

double Plasticity::alpha(int32_t cell) const {
  double out = 0;
  for (size_t u = 0; u < alpha_.size(); ++u) {
    if (unit_cell_[u] == cell) out = std::max(out, alpha_[u]);
  }
  return out;
}

double Plasticity::max_alpha() const {
  double out = 0;
  for (double a : alpha_) out = std::max(out, a);
  return out;
}

double Plasticity::dissipation() const {
  double sum = 0;
  for (double d : dissipation_) sum += d;
  return sum;
}

int32_t Plasticity::yielded_cells() const {
  std::vector<uint8_t> yielded(laws_.size(), 0);
  for (size_t u = 0; u < alpha_.size(); ++u) {
    if (alpha_[u] > 0) yielded[unit_cell_[u]] = 1;
  }
  return static_cast<int32_t>(std::count(yielded.begin(), yielded.end(), 1));
}

Points Plasticity::RestDisplacement(const models::CellCorotation& model,
                                    int64_t controls) const {
  Points sum = Points::Zero(controls, 3);
  std::vector<double> count(controls, 0.0);
  if (offsets_.empty() || static_cast<int64_t>(first_.size()) != model.cells()) return sum;
  for (int32_t c = 0; c < model.cells(); ++c) {
    const int32_t* support = model.support(c);
    const double* up = offsets_.data() + 3 * static_cast<int64_t>(model.support_first(c));
    for (int32_t a = 0; a < model.support_size(c); ++a) {
      sum.row(support[a]) += Eigen::RowVector3d(up[3 * a], up[3 * a + 1], up[3 * a + 2]);
      count[support[a]] += 1;
    }
  }
  for (int64_t i = 0; i < controls; ++i) {
    if (count[i] > 0) sum.row(i) /= count[i];
  }
  return sum;
}

int32_t Plasticity::CarryFrom(const Plasticity& old, const std::vector<int32_t>& source,
                              const std::vector<std::vector<int32_t>>& entry_map) {
  int32_t carried = 0;
  for (size_t u = 0; u < first_.size() && u < source.size(); ++u) {
    const int32_t s = source[u];
    if (s < 0 || s >= old.units() || old.offsets_.empty()) continue;
    const std::vector<int32_t>& map = entry_map[u];
    const int n = size_[u];
    if (map.empty() && old.size_[s] != n) continue;
    double* to = offsets_.data() + 3 * static_cast<int64_t>(first_[u]);
    const double* from = old.offsets_.data() + 3 * static_cast<int64_t>(old.first_[s]);
    for (int a = 0; a < n; ++a) {
      const int b = map.empty() ? a : map[a];
      for (int k = 0; k < 3; ++k) to[3 * a + k] = from[3 * b + k];
    }
    alpha_[u] = old.alpha_[s];
    dissipation_[u] = old.dissipation_[s];
    ++carried;
  }
  UpdateActive();
  return carried;
}

int32_t Plasticity::EstimateChanged(const Plasticity& old,
                                    const models::CellCorotation& old_model,
                                    const models::CellCorotation& model, const Points& old_rest,
                                    const Points& rest, const std::vector<int32_t>& point_source,
                                    const std::vector<int32_t>& cell_source,
                                    const std::vector<int32_t>& carried) {
  if (old.offsets_.empty() || offsets_.empty() ||
      static_cast<int32_t>(old.first_.size()) != old_model.cells() ||
      static_cast<int32_t>(first_.size()) != model.cells()) {
    return 0;
  }
  const Points averaged = old.RestDisplacement(old_model, old_rest.rows());
  auto row = [](const Points& p, int32_t i) -> Eigen::Vector3d { return p.row(i).transpose(); };
  int32_t estimated = 0;
  std::vector<Eigen::Vector3d> xs, us;
  for (int32_t c = 0; c < model.cells(); ++c) {
    if (c < static_cast<int32_t>(carried.size()) && carried[c] >= 0) continue;
    const int32_t src = c < static_cast<int32_t>(cell_source.size()) ? cell_source[c] : -1;
    const bool sourced = src >= 0 && src < old_model.cells();
    const int32_t* was = sourced ? old_model.support(src) : nullptr;
    const int32_t was_n = sourced ? old_model.support_size(src) : 0;
    const double* from = sourced ? old.offsets_.data() + 3 * static_cast<int64_t>(old.first_[src])
                                 : nullptr;
    const int32_t* now = model.support(c);
    const int32_t n = model.support_size(c);
    xs.clear();
    us.clear();
    if (sourced) {
      for (int32_t b = 0; b < was_n; ++b) {
        xs.push_back(row(old_rest, was[b]));
        us.emplace_back(from[3 * b], from[3 * b + 1], from[3 * b + 2]);
      }
    } else {
      for (int32_t a = 0; a < n; ++a) {
        const int32_t o = point_source[now[a]];
        if (o < 0) continue;
        xs.push_back(row(old_rest, o));
        us.push_back(row(averaged, o));
      }
    }
    if (xs.empty()) continue;
    const AffineFit fit = FitAffine(xs, us);
    double* to = offsets_.data() + 3 * static_cast<int64_t>(first_[c]);
    bool moved = false;
    for (int32_t a = 0; a < n; ++a) {
      const int32_t o = point_source[now[a]];
      Eigen::Vector3d u = fit.At(row(rest, now[a]));
      if (sourced && o >= 0) {
        const int32_t* at = std::lower_bound(was, was + was_n, o);
        if (at != was + was_n && *at == o) {
          const double* f = from + 3 * (at - was);
          u = Eigen::Vector3d(f[0], f[1], f[2]);
        }
      } else if (!sourced && o >= 0) {
        u = row(averaged, o);
      }
      for (int k = 0; k < 3; ++k) to[3 * a + k] = u[k];
      moved = moved || u != Eigen::Vector3d::Zero();
    }
    alpha_[c] = sourced ? old.alpha_[src] : 0.0;
    dissipation_[c] = 0;
    if (moved) ++estimated;
  }
  UpdateActive();
  return estimated;
}

std::string Plasticity::SaveState() const {
  std::string out(kStateMagic, 4);
  Put<uint64_t>(out, laws_.size());
  for (const FlowLaw& l : laws_) {
    Put(out, l.yield);
    Put(out, l.rate);
    Put(out, l.hardening);
    Put(out, l.poisson);
  }
  PutDoubles(out, offsets_);
  PutDoubles(out, alpha_);
  PutDoubles(out, dissipation_);
  return out;
}

absl::StatusOr<Plasticity::State> Plasticity::ParseState(std::string_view bytes, int32_t cells,
                                                        Units units) {
  auto fail = [](const std::string& what) {
    return absl::DataLossError(absl::StrCat("plasticity state: ", what));
  };
  if (bytes.size() < 4 || std::memcmp(bytes.data(), kStateMagic, 4) != 0) {
    return fail("no plasticity header");
  }
  Reader r(bytes.substr(4));
  uint64_t n = 0;
  if (!r.Get(n) || n != static_cast<uint64_t>(cells)) {
    return fail(absl::StrCat("the state has ", n, " cells, the solid ", cells));
  }
  State s;
  s.laws.resize(n);
  for (FlowLaw& l : s.laws) {
    if (!r.Get(l.yield) || !r.Get(l.rate) || !r.Get(l.hardening) || !r.Get(l.poisson)) {
      return fail("truncated flow laws");
    }
    if (!(l.yield >= 0 && l.rate >= 0 && l.hardening >= 0 && std::isfinite(l.yield) &&
          std::isfinite(l.rate) && std::isfinite(l.hardening) && l.poisson >= 0 && l.poisson < 0.5)) {
      return fail("a flow law out of range");
    }
  }
  if (!r.Doubles(s.offsets, 3 * static_cast<uint64_t>(units.entries))) {
    return fail("offsets: wrong count or non-finite");
  }
  if (!r.Doubles(s.alpha, units.units)) return fail("plastic strains: wrong count or non-finite");
  if (!r.Doubles(s.dissipation, units.units)) {
    return fail("dissipation: wrong count or non-finite");
  }
  if (!r.at_end()) return fail("bytes after the end");
  return s;
}

void Plasticity::set_state(State s) {
  laws_ = std::move(s.laws);
  offsets_ = std::move(s.offsets);
  alpha_ = std::move(s.alpha);
  dissipation_ = std::move(s.dissipation);
  UpdateActive();
}

void Plasticity::set_laws(std::vector<FlowLaw> laws) {
  laws_ = std::move(laws);
  UpdateActive();
}

void Plasticity::Checkpoint() {
  checkpoint_.offsets = offsets_;
  checkpoint_.alpha = alpha_;
  checkpoint_.dissipation = dissipation_;
}

void Plasticity::Rollback() {
  offsets_ = checkpoint_.offsets;
  alpha_ = checkpoint_.alpha;
  dissipation_ = checkpoint_.dissipation;
  // (active_ only grows with a flow, and only where a law yields: a cell
  // active before the step is active after it.)
}

}  // namespace dynsolid::material
