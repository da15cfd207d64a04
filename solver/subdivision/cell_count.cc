#include "solver/subdivision/cell_count.h"

#include <algorithm>
#include <utility>

namespace dynsolid::subdivision {

std::vector<int64_t> CellVertexValences(const std::vector<std::vector<int32_t>>& faces) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  for (const auto& loop : faces) {
    for (size_t i = 0; i < loop.size(); ++i) {
      const int32_t a = loop[i], b = loop[(i + 1) % loop.size()];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<int32_t> ends;
  for (const auto& [a, b] : edges) {
    ends.push_back(a);
    ends.push_back(b);
  }
  std::sort(ends.begin(), ends.end());
  std::vector<int64_t> valences;
  for (size_t i = 0; i < ends.size();) {
    size_t j = i;
    while (j < ends.size() && ends[j] == ends[i]) ++j;
    valences.push_back(static_cast<int64_t>(j - i));
    i = j;
  }
  return valences;
}

int64_t DescendantsOfVertexChild(int64_t k, int levels) {
  int64_t own_kind = 1, hexahedra = 0;
  for (int l = 1; l < levels; ++l) {
    hexahedra = 8 * hexahedra + 2 * k * own_kind;
    own_kind *= 2;
  }
  return own_kind + hexahedra;
}

int64_t EstimateFineCells(const mesh::MeshInput& control, std::span<const int32_t> refine_cells,
                          int levels) {
  const int64_t num_cells = static_cast<int64_t>(control.cells.size());
  std::vector<uint8_t> refined(num_cells, 0);
  for (int32_t c : refine_cells) {
    if (c >= 0 && c < num_cells) refined[c] = 1;
  }
  int64_t cells = 0;
  for (int64_t c = 0; c < num_cells; ++c) {
    // A locally refined cell is one level ahead of the others.
    const int l = levels + refined[c];
    if (l == 0) {
      ++cells;
      continue;
    }
    for (int64_t k : CellVertexValences(control.cells[c])) cells += DescendantsOfVertexChild(k, l);
  }
  return cells;
}

}  // namespace dynsolid::subdivision
