#include "server/material_diff.h"

#include <cstring>
#include <map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/fem/element_set.h"
#include "solver/scene/build.h"
#include "solver/solid/solid.h"

namespace dynsolid::server {
namespace {

// The head's layout (solid_state.cc SaveStateParts): magic 8, version 4,
// fingerprint 16, payload size 8; time, steps, rollbacks 8 each, sub-steps
// 4, omega and stable step 8 each, then forces_valid, the last strain
// energy (8) and ledger_rebase.
constexpr size_t kPayloadSizeAt = 28;
constexpr size_t kHeaderBytes = 36;
constexpr size_t kForcesValidAt = 80;
constexpr size_t kLedgerRebaseAt = 89;

template <typename T>
bool Get(const std::string& s, size_t* pos, T* v) {
  if (*pos + sizeof(T) > s.size()) return false;
  std::memcpy(v, s.data() + *pos, sizeof(T));
  *pos += sizeof(T);
  return true;
}
template <typename T>
void Put(std::string* s, T v) {
  s->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

const std::vector<double>& Samples(const ElementMaterials& m, int32_t e) {
  return m.arrays[m.element_array[e]];
}

}  // namespace

absl::StatusOr<ElementMaterials> MaterialsOf(const solid::Solid& solid) {
  absl::StatusOr<ElementMaterials> m = ParseMaterialSection(*solid.SaveStateParts().section);
  if (!m.ok()) return m;
  const scene::Discretization& d = solid.discretization();
  const Points rest = d.node_matrix * d.control().positions();
  const fem::ElementSet& es = d.elements;
  const std::vector<int32_t>* nodes[fem::kElementKinds] = {&es.cubic_nodes, &es.linear_nodes,
                                                           &es.pyramid_nodes};
  const int32_t per[fem::kElementKinds] = {64, 8, 5};
  std::string buffer;
  for (int kind = 0; kind < fem::kElementKinds; ++kind) {
    const int32_t n = static_cast<int32_t>(nodes[kind]->size()) / per[kind];
    for (int32_t e = 0; e < n; ++e) {
      buffer.assign(1, static_cast<char>(kind));
      for (int32_t k = 0; k < per[kind]; ++k) {
        const int32_t node = (*nodes[kind])[static_cast<size_t>(e) * per[kind] + k];
        for (int c = 0; c < 3; ++c) Put<double>(&buffer, rest(node, c));
      }
      m->keys.push_back(solid::WordChecksum(buffer));
    }
  }
  if (m->keys.size() != m->element_array.size()) {
    return absl::InternalError(absl::StrCat("material section: ", m->element_array.size(),
                                            " elements, the solid has ", m->keys.size()));
  }
  return m;
}

absl::StatusOr<ElementMaterials> ParseMaterialSection(const std::string& s) {
  ElementMaterials m;
  size_t pos = 0;
  uint64_t n = 0;
  auto bad = [&](const char* what) {
    return absl::DataLossError(absl::StrCat("material section: ", what, " at byte ", pos));
  };
  if (!Get(s, &pos, &n) || n > s.size() / 8) return bad("array count");
  m.arrays.resize(n);
  for (auto& a : m.arrays) {
    uint64_t k = 0;
    if (!Get(s, &pos, &k) || k % 4 != 0 || pos + 8 * k > s.size()) return bad("array");
    a.resize(k);
    std::memcpy(a.data(), s.data() + pos, 8 * k);
    pos += 8 * k;
  }
  while (pos < s.size()) {
    uint64_t count = 0;
    if (!Get(s, &pos, &count) || pos + 4 * count > s.size()) return bad("element block");
    m.block_sizes.push_back(static_cast<int32_t>(count));
    for (uint64_t e = 0; e < count; ++e) {
      int32_t a = 0;
      Get(s, &pos, &a);
      if (a < 0 || static_cast<uint64_t>(a) >= n) return bad("element array index");
      m.element_array.push_back(a);
    }
  }
  return m;
}

std::string WriteMaterialSection(const ElementMaterials& m) {
  std::string out;
  Put<uint64_t>(&out, m.arrays.size());
  for (const auto& a : m.arrays) {
    Put<uint64_t>(&out, a.size());
    out.append(reinterpret_cast<const char*>(a.data()), 8 * a.size());
  }
  size_t e = 0;
  for (int32_t count : m.block_sizes) {
    Put<uint64_t>(&out, static_cast<uint64_t>(count));
    for (int32_t k = 0; k < count; ++k) Put<int32_t>(&out, m.element_array[e++]);
  }
  return out;
}

absl::Status AddPaintDiff(const ElementMaterials& before, const ElementMaterials& after,
                          persist::PaintChange* change) {
  if (before.element_array.size() != after.element_array.size() ||
      after.keys.size() != after.element_array.size()) {
    return absl::InternalError("paint: the element count changed");
  }
  // What the change holds already, by element key.
  std::map<uint64_t, std::pair<std::vector<double>, std::vector<double>>> diff;
  size_t at = 0;
  for (int i = 0; i < change->elements_size(); ++i) {
    const int32_t c = change->counts(i);
    auto& d = diff[change->elements(i)];
    d.first.assign(change->before().begin() + at, change->before().begin() + at + c);
    d.second.assign(change->after().begin() + at, change->after().begin() + at + c);
    at += c;
  }
  for (int32_t e = 0; e < static_cast<int32_t>(after.element_array.size()); ++e) {
    const std::vector<double>& b = Samples(before, e);
    const std::vector<double>& a = Samples(after, e);
    if (b.size() == a.size() && std::memcmp(b.data(), a.data(), 8 * b.size()) == 0) continue;
    auto it = diff.find(after.keys[e]);
    if (it == diff.end()) {
      diff[after.keys[e]] = {b, a};
    } else {
      it->second.second = a;
    }
  }
  change->clear_elements();
  change->clear_counts();
  change->clear_before();
  change->clear_after();
  for (const auto& [e, d] : diff) {
    change->add_elements(e);
    change->add_counts(static_cast<int32_t>(d.first.size()));
    change->mutable_before()->Add(d.first.begin(), d.first.end());
    change->mutable_after()->Add(d.second.begin(), d.second.end());
  }
  return absl::OkStatus();
}

absl::StatusOr<int32_t> FlipPaint(const persist::PaintChange& change, bool undo,
                                  ElementMaterials* now) {
  const auto& from = undo ? change.after() : change.before();
  const auto& to = undo ? change.before() : change.after();
  // New arrays for the elements that flip; then the arrays compacted in
  // order of first use (the same input, the same bytes).
  std::vector<std::vector<double>> arrays = now->arrays;
  std::vector<int32_t> element_array = now->element_array;
  std::map<uint64_t, int32_t> by_key;
  for (size_t e = 0; e < now->keys.size(); ++e) by_key.emplace(now->keys[e], static_cast<int32_t>(e));
  int32_t flipped = 0;
  size_t at = 0;
  for (int i = 0; i < change.elements_size(); ++i) {
    const int32_t c = change.counts(i);
    auto found = by_key.find(change.elements(i));
    if (found == by_key.end()) {  // rebuilt by an edit since
      at += c;
      continue;
    }
    const int32_t e = found->second;
    const std::vector<double>& cur = arrays[element_array[e]];
    if (static_cast<int32_t>(cur.size()) == c &&
        std::memcmp(cur.data(), from.data() + at, 8 * static_cast<size_t>(c)) == 0) {
      arrays.emplace_back(to.begin() + at, to.begin() + at + c);
      element_array[e] = static_cast<int32_t>(arrays.size() - 1);
      ++flipped;
    }
    at += c;
  }
  if (flipped == 0) return 0;
  std::map<std::vector<double>, int32_t> index;
  ElementMaterials out;
  out.block_sizes = now->block_sizes;
  out.keys = now->keys;
  out.element_array.resize(element_array.size());
  for (size_t e = 0; e < element_array.size(); ++e) {
    const std::vector<double>& a = arrays[element_array[e]];
    auto [it, added] = index.emplace(a, static_cast<int32_t>(out.arrays.size()));
    if (added) out.arrays.push_back(a);
    out.element_array[e] = it->second;
  }
  *now = std::move(out);
  return flipped;
}

std::string StateWithMaterial(const solid::SavedState& now, const std::string& section) {
  solid::SavedState s;
  s.head = now.head;
  const uint64_t payload = s.head.size() - kHeaderBytes + section.size() + 8;
  std::memcpy(s.head.data() + kPayloadSizeAt, &payload, sizeof(payload));
  s.head[kForcesValidAt] = 0;
  s.head[kLedgerRebaseAt] = 1;
  s.head_sum = solid::WordChecksum(s.head);
  s.section = std::make_shared<const std::string>(section);
  s.section_sum = solid::WordChecksum(section);
  return solid::Solid::JoinState(s);
}

}  // namespace dynsolid::server
