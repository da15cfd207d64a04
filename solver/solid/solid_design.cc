// A design's own state (scene.proto Design; design.h): Solid::SaveDesign
// writes the materials as painted and the clay's rest shape; Create reads
// them back through DesignMaterials and DesignClay.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/fem/element_data.h"
#include "solver/solid/design.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

const std::vector<int32_t>& NodesOf(const fem::ElementSet& e, int kind) {
  return kind == 0 ? e.cubic_nodes : kind == 1 ? e.linear_nodes : e.pyramid_nodes;
}

// An element's key: its rest nodes' bits, sorted (the layout reorders an
// element's nodes when it aligns its axes; the set stays).
Key128 NodeSetKey(const fem::NodeMatrixX3& x) {
  std::vector<std::array<uint64_t, 3>> rows(x.rows());
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    for (int r = 0; r < 3; ++r) {
      const double v = x(i, r) == 0.0 ? 0.0 : x(i, r);  // -0 as +0
      std::memcpy(&rows[i][r], &v, sizeof(double));
    }
  }
  std::sort(rows.begin(), rows.end());
  Hash128 h;
  h.Mix(rows.size());
  for (const auto& row : rows) {
    for (uint64_t w : row) h.Mix(w);
  }
  return h.value();
}

using SampleKey = std::array<double, 4>;
SampleKey KeyOf(const models::MaterialPoint& m) { return {m.young, m.poisson, m.density, m.damping}; }

absl::Status CheckSample(const Design::Sample& m, int i) {
  const std::string at = absl::StrCat("design.materials[", i, "]");
  if (!(m.young_modulus() > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".young_modulus: ", m.young_modulus(), " is not > 0"));
  }
  if (!(m.poisson_ratio() > -1 && m.poisson_ratio() < 0.5)) {
    return absl::InvalidArgumentError(
        absl::StrCat(at, ".poisson_ratio: ", m.poisson_ratio(), " is outside (-1, 0.5)"));
  }
  if (!(m.density() > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".density: ", m.density(), " is not > 0"));
  }
  if (!(m.damping() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".damping: ", m.damping(), " is not >= 0"));
  }
  return absl::OkStatus();
}

absl::Status CheckLaw(const Design::FlowLaw& l, int i) {
  const std::string at = absl::StrCat("design.flow_laws[", i, "]");
  if (!(l.yield_strain() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".yield_strain: ", l.yield_strain(), " is not >= 0"));
  }
  if (!(l.flow_rate() > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".flow_rate: ", l.flow_rate(), " is not > 0"));
  }
  if (!(l.hardening() >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(at, ".hardening: ", l.hardening(), " is not >= 0"));
  }
  if (!(l.poisson_ratio() > -1 && l.poisson_ratio() < 0.5)) {
    return absl::InvalidArgumentError(
        absl::StrCat(at, ".poisson_ratio: ", l.poisson_ratio(), " is outside (-1, 0.5)"));
  }
  return absl::OkStatus();
}

}  // namespace

Design Solid::SaveDesign() const {
  const Impl& im = *impl_;
  const models::ElementLayout& layout = *im.layout;
  Design out;
  // The distinct samples, numbered as first met; the runs over every
  // element's samples in order.
  std::map<SampleKey, int32_t> index;
  int32_t run_of = -1, run = 0;
  auto flush = [&] {
    if (run > 0) {
      out.add_sample_runs(run);
      out.add_sample_runs(run_of);
    }
  };
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const models::ElementBlock& block = layout.blocks[kind];
    out.add_elements(block.size());
    for (int32_t e = 0; e < block.size(); ++e) {
      const std::vector<models::MaterialPoint>& samples =
          layout.materials[block.groups[block.group[e]].material];
      for (const models::MaterialPoint& m : samples) {
        auto [it, added] = index.try_emplace(KeyOf(m), static_cast<int32_t>(index.size()));
        if (added) {
          Design::Sample* s = out.add_materials();
          s->set_young_modulus(m.young);
          s->set_poisson_ratio(m.poisson);
          s->set_density(m.density);
          s->set_damping(m.damping);
        }
        if (it->second == run_of) {
          ++run;
        } else {
          flush();
          run_of = it->second;
          run = 1;
        }
      }
    }
  }
  flush();
  if (im.plasticity != nullptr) {
    const material::Plasticity::State st = im.plasticity->state();
    std::map<std::array<double, 4>, int32_t> laws;
    for (const material::FlowLaw& l : st.laws) {
      auto [it, added] = laws.try_emplace(std::array<double, 4>{l.yield, l.rate, l.hardening, l.poisson},
                                          static_cast<int32_t>(laws.size()));
      if (added) {
        Design::FlowLaw* f = out.add_flow_laws();
        f->set_yield_strain(l.yield);
        f->set_flow_rate(l.rate);
        f->set_hardening(l.hardening);
        f->set_poisson_ratio(l.poisson);
      }
      out.add_cell_flow(it->second);
    }
    out.mutable_plastic_offsets()->Add(st.offsets.begin(), st.offsets.end());
    out.mutable_plastic_strain()->Add(st.alpha.begin(), st.alpha.end());
  }
  return out;
}

absl::StatusOr<std::unique_ptr<DesignMaterials>> DesignMaterials::Make(
    const Design& design, const fem::ElementSet& elements, const Points& rest) {
  for (int i = 0; i < design.materials_size(); ++i) {
    if (absl::Status s = CheckSample(design.materials(i), i); !s.ok()) return s;
  }
  std::array<int32_t, fem::kElementKinds> counts{elements.num_cubic(), elements.num_linear(),
                                                 elements.num_pyramid()};
  if (design.elements_size() != fem::kElementKinds ||
      !std::equal(counts.begin(), counts.end(), design.elements().begin())) {
    std::string given;
    for (int32_t n : design.elements()) absl::StrAppend(&given, given.empty() ? "" : ", ", n);
    return absl::InvalidArgumentError(absl::StrCat(
        "design.elements: [", given, "] are not this scene's elements per kind [", counts[0], ", ",
        counts[1], ", ", counts[2], "] (cubic, trilinear, pyramid): the design was saved for "
        "another control mesh or subdivision level"));
  }
  if (design.sample_runs_size() % 2 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "design.sample_runs: ", design.sample_runs_size(), " numbers, not (length, material) pairs"));
  }
  auto out = std::make_unique<DesignMaterials>();
  int64_t total = 0;
  std::array<fem::KindTable, fem::kElementKinds> tables;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    tables[kind] = fem::MakeKindTable(static_cast<fem::ElementKind>(kind));
    total += static_cast<int64_t>(counts[kind]) * tables[kind].points;
  }
  // The runs are read as the elements take their samples; equal arrays are
  // kept once (an unpainted design is one array per kind), so a design
  // costs memory for what was painted, not for every sample.
  int run = 0;           // index of the current (length, material) pair
  int32_t left = 0;      // samples left in it
  int64_t taken = 0;
  const Design::Sample* current = nullptr;
  auto next_sample = [&]() -> absl::StatusOr<const Design::Sample*> {
    while (left == 0) {
      if (2 * run >= design.sample_runs_size()) {
        return absl::InvalidArgumentError(absl::StrCat("design.sample_runs: ", taken,
                                                       " samples, this scene's elements have ", total));
      }
      const int32_t length = design.sample_runs(2 * run), m = design.sample_runs(2 * run + 1);
      if (length < 1 || length > total - taken) {
        return absl::InvalidArgumentError(absl::StrCat(
            "design.sample_runs[", 2 * run, "]: run length ", length, " is not in [1, ",
            total - taken, "] (the samples left of ", total, ")"));
      }
      if (m < 0 || m >= design.materials_size()) {
        return absl::InvalidArgumentError(absl::StrCat("design.sample_runs[", 2 * run + 1,
                                                       "]: material ", m, " is out of range [0, ",
                                                       design.materials_size(), ")"));
      }
      current = &design.materials(m);
      left = length;
      ++run;
    }
    --left;
    ++taken;
    return current;
  };
  std::unordered_map<uint64_t, std::vector<int32_t>> interned;  // content hash -> arrays
  std::vector<models::MaterialPoint> samples;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const int points = tables[kind].points, nodes = tables[kind].nodes;
    const std::vector<int32_t>& ids = NodesOf(elements, kind);
    fem::NodeMatrixX3 x(nodes, 3);
    for (int32_t e = 0; e < counts[kind]; ++e) {
      samples.resize(points);
      Hash128 h;
      for (int q = 0; q < points; ++q) {
        ASSIGN_OR_RETURN(const Design::Sample* s, next_sample());
        samples[q] = {s->young_modulus(), s->poisson_ratio(), s->density(), s->damping()};
        h.Doubles(&samples[q].young, 1);
        h.Doubles(&samples[q].poisson, 1);
        h.Doubles(&samples[q].density, 1);
        h.Doubles(&samples[q].damping, 1);
      }
      std::vector<int32_t>& same = interned[h.value().first];
      int32_t index = -1;
      for (int32_t k : same) {
        if (out->arrays_[k] == samples) index = k;
      }
      if (index < 0) {
        index = static_cast<int32_t>(out->arrays_.size());
        out->arrays_.push_back(samples);
        same.push_back(index);
      }
      for (int i = 0; i < nodes; ++i) x.row(i) = rest.row(ids[static_cast<size_t>(e) * nodes + i]);
      Key128 key = NodeSetKey(x);
      key.first ^= static_cast<uint64_t>(kind);
      out->by_nodes_.emplace(key, index);
    }
  }
  if (taken != total || left != 0 || 2 * run != design.sample_runs_size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "design.sample_runs: more samples than this scene's elements have (", total, ")"));
  }
  return out;
}

const std::vector<models::MaterialPoint>* DesignMaterials::Find(int kind,
                                                                const fem::NodeMatrixX3& x) const {
  Key128 key = NodeSetKey(x);
  key.first ^= static_cast<uint64_t>(kind);
  const auto it = by_nodes_.find(key);
  return it == by_nodes_.end() ? nullptr : &arrays_[it->second];
}

absl::StatusOr<std::optional<material::Plasticity::State>> DesignClay(
    const Design& design, int32_t cells, material::Plasticity::Units units) {
  if (design.cell_flow_size() == 0 && design.flow_laws_size() == 0 &&
      design.plastic_offsets_size() == 0 && design.plastic_strain_size() == 0) {
    return std::nullopt;
  }
  for (int i = 0; i < design.flow_laws_size(); ++i) {
    if (absl::Status s = CheckLaw(design.flow_laws(i), i); !s.ok()) return s;
  }
  if (design.cell_flow_size() != cells) {
    return absl::InvalidArgumentError(absl::StrCat("design.cell_flow: ", design.cell_flow_size(),
                                                   " laws for ", cells, " control cells"));
  }
  material::Plasticity::State st;
  for (int c = 0; c < cells; ++c) {
    const int32_t l = design.cell_flow(c);
    if (l < 0 || l >= design.flow_laws_size()) {
      return absl::InvalidArgumentError(absl::StrCat("design.cell_flow[", c, "]: law ", l,
                                                     " is out of range [0, ", design.flow_laws_size(), ")"));
    }
    const Design::FlowLaw& f = design.flow_laws(l);
    st.laws.push_back({f.yield_strain(), f.flow_rate(), f.hardening(), f.poisson_ratio()});
  }
  if (units.units == 0) {
    return absl::InvalidArgumentError(
        "design.cell_flow: clay needs solver.model COROTATIONAL (this scene's model has no flow units)");
  }
  const int64_t entries = 3 * units.entries;
  if (design.plastic_offsets_size() != entries && design.plastic_offsets_size() != 0) {
    return absl::InvalidArgumentError(absl::StrCat("design.plastic_offsets: ", design.plastic_offsets_size(),
                                                   " numbers, this solid's flow units have ", entries));
  }
  if (design.plastic_strain_size() != units.units && design.plastic_strain_size() != 0) {
    return absl::InvalidArgumentError(absl::StrCat("design.plastic_strain: ", design.plastic_strain_size(),
                                                   " numbers for ", units.units, " flow units"));
  }
  st.offsets.assign(design.plastic_offsets().begin(), design.plastic_offsets().end());
  st.offsets.resize(entries, 0.0);
  st.alpha.assign(design.plastic_strain().begin(), design.plastic_strain().end());
  st.alpha.resize(units.units, 0.0);
  for (int32_t u = 0; u < units.units; ++u) {
    if (!(st.alpha[u] >= 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("design.plastic_strain[", u, "]: ", st.alpha[u], " is not >= 0"));
    }
  }
  st.dissipation.assign(units.units, 0.0);
  return st;
}

}  // namespace dynsolid::solid
