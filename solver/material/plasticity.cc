#include "solver/material/plasticity.h"

#include <algorithm>
#include <cmath>
#include <cstring>

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

}  // namespace

FlowLaw FlowLawOf(const Material& m) {
  FlowLaw law;
  law.yield = m.yield_strain();
  law.rate = m.flow_rate();
  law.hardening = m.hardening();
  law.poisson = m.poisson_ratio();
  return law;
}

CellPlasticity::CellPlasticity(std::vector<FlowLaw> laws) : laws_(std::move(laws)) {
  alpha_.assign(laws_.size(), 0.0);
  dissipation_.assign(laws_.size(), 0.0);
  UpdateActive();
}

void CellPlasticity::UpdateActive() {
  active_.assign(laws_.size(), 0);
  for (size_t c = 0; c < laws_.size(); ++c) {
    bool moved = alpha_[c] > 0;
    if (!moved && !offsets_.empty() && c < first_.size()) {
      const double* up = offsets_.data() + 3 * static_cast<int64_t>(first_[c]);
      for (int e = 0; e < 3 * size_[c] && !moved; ++e) moved = up[e] != 0;
    }
    active_[c] = laws_[c].yield > 0 || moved;
  }
}

bool CellPlasticity::any_yields() const {
  return std::any_of(laws_.begin(), laws_.end(), [](const FlowLaw& l) { return l.yield > 0; });
}

void CellPlasticity::Attach(models::CellCorotation& model) {
  const int32_t cells = model.cells();
  first_.resize(cells);
  size_.resize(cells);
  scale_.assign(cells, 0.0);
  std::vector<double> u;
  for (int32_t c = 0; c < cells; ++c) {
    first_[c] = model.support_first(c);
    size_[c] = model.support_size(c);
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
  entries_ = model.support_entries();
  if (offsets_.size() != static_cast<size_t>(3 * entries_)) offsets_.assign(3 * entries_, 0.0);
  UpdateActive();
  model.set_flow(this);
}

void CellPlasticity::Flow(int32_t cell, const double* u, const double* ku) {
  const FlowLaw& law = laws_[cell];
  if (!(law.yield > 0) || !(scale_[cell] > 0)) return;
  const int n = 3 * size_[cell];
  double twice_w = 0;
  for (int e = 0; e < n; ++e) twice_w += u[e] * ku[e];
  if (!(twice_w > 0)) return;
  const double eps = std::sqrt(twice_w / scale_[cell]);
  const double y = law.yield + law.hardening * alpha_[cell];
  if (!(eps > y)) return;
  // The return to the yield surface with linear hardening: eps - d = y +
  // hardening d for the plastic strain increment d = lambda eps, all of it
  // when the rate and step allow, else the fraction rate * dt.
  const double lambda = (1.0 - y / eps) / (1.0 + law.hardening) * std::min(1.0, law.rate * dt_);
  double* up = offsets_.data() + 3 * static_cast<int64_t>(first_[cell]);
  for (int e = 0; e < n; ++e) up[e] += lambda * u[e];
  alpha_[cell] += lambda * eps;
  dissipation_[cell] += lambda * twice_w;
}

double CellPlasticity::dissipation() const {
  double sum = 0;
  for (double d : dissipation_) sum += d;
  return sum;
}

int32_t CellPlasticity::yielded_cells() const {
  return static_cast<int32_t>(std::count_if(alpha_.begin(), alpha_.end(), [](double a) { return a > 0; }));
}

Points CellPlasticity::RestDisplacement(const models::CellCorotation& model,
                                        int64_t controls) const {
  Points sum = Points::Zero(controls, 3);
  std::vector<double> count(controls, 0.0);
  if (offsets_.empty()) return sum;
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

std::string CellPlasticity::SaveState() const {
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

absl::StatusOr<CellPlasticity::State> CellPlasticity::ParseState(std::string_view bytes,
                                                                int32_t cells, int64_t entries) {
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
  if (!r.Doubles(s.offsets, 3 * static_cast<uint64_t>(entries))) {
    return fail("offsets: wrong count or non-finite");
  }
  if (!r.Doubles(s.alpha, n)) return fail("plastic strains: wrong count or non-finite");
  if (!r.Doubles(s.dissipation, n)) return fail("dissipation: wrong count or non-finite");
  if (!r.at_end()) return fail("bytes after the end");
  return s;
}

void CellPlasticity::set_state(State s) {
  laws_ = std::move(s.laws);
  offsets_ = std::move(s.offsets);
  alpha_ = std::move(s.alpha);
  dissipation_ = std::move(s.dissipation);
  UpdateActive();
}

void CellPlasticity::set_laws(std::vector<FlowLaw> laws) {
  laws_ = std::move(laws);
  UpdateActive();
}

void CellPlasticity::Checkpoint() {
  checkpoint_.offsets = offsets_;
  checkpoint_.alpha = alpha_;
  checkpoint_.dissipation = dissipation_;
}

void CellPlasticity::Rollback() {
  offsets_ = checkpoint_.offsets;
  alpha_ = checkpoint_.alpha;
  dissipation_ = checkpoint_.dissipation;
  // (active_ only grows with a flow, and only where a law yields: a cell
  // active before the step is active after it.)
}

}  // namespace dynsolid::material
