// MergeFaces: join two boundary faces with one connecting cell (docs/model.md 8).
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/sculpt/edit_common.h"

namespace dynsolid::sculpt {
namespace {

absl::Status CheckFace(const mesh::CellComplex& rest, int32_t face, absl::string_view field) {
  if (face < 0 || face >= rest.num_faces()) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": face ", face, " is out of range [0, ", rest.num_faces(), ")"));
  }
  if (!rest.face_is_boundary(face)) {
    const auto& fc = rest.face_cells(face);
    return absl::InvalidArgumentError(absl::StrCat(field, ": face ", face,
                                                   " is interior (shared by cells ", fc[0], " and ",
                                                   fc[1], "); only boundary faces merge"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<EditResult> MergeFaces(const mesh::CellComplex& rest, const Points& current,
                                      const std::vector<uint8_t>& sharp, int32_t face_a,
                                      int32_t face_b) {
  RETURN_IF_ERROR(internal::CheckState(rest, current, sharp));
  RETURN_IF_ERROR(CheckFace(rest, face_a, "face_a"));
  RETURN_IF_ERROR(CheckFace(rest, face_b, "face_b"));
  if (face_a == face_b) {
    return absl::InvalidArgumentError(
        absl::StrCat("face_b: face ", face_b, " is face_a; merge needs two distinct faces"));
  }
  const auto a = rest.face_vertices(face_a);
  const auto b = rest.face_vertices(face_b);
  const int32_t k = static_cast<int32_t>(a.size());
  if (static_cast<int32_t>(b.size()) != k) {
    return absl::InvalidArgumentError(absl::StrCat("face_b: face ", face_b, " has ", b.size(),
                                                   " vertices but face_a (face ", face_a, ") has ",
                                                   k, "; merge needs equal counts"));
  }
  for (int32_t v : a) {
    for (int32_t w : b) {
      if (v == w) {
        return absl::InvalidArgumentError(
            absl::StrCat("face_b: faces ", face_a, " and ", face_b, " share vertex ", v,
                         "; the connecting cell would be degenerate"));
      }
    }
  }

  // a_i pairs with b_{(s - i) mod k}: the top of the new cell is face_b
  // reversed, as it must be for face_b to become interior.
  const Points& p = rest.positions();
  int32_t best_s = 0;
  double best = std::numeric_limits<double>::infinity();
  for (int32_t s = 0; s < k; ++s) {
    double sum = 0.0;
    for (int32_t i = 0; i < k; ++i) sum += (p.row(a[i]) - p.row(b[((s - i) % k + k) % k])).norm();
    if (sum < best) {
      best = sum;
      best_s = s;
    }
  }
  std::vector<int32_t> top(k), bottom(k);
  for (int32_t i = 0; i < k; ++i) {
    top[i] = b[((best_s - i) % k + k) % k];
    bottom[i] = a[(k - i) % k];
  }

  EditResult result;
  result.mesh = internal::ToInput(rest);
  result.current = current;
  result.vertex_sources = internal::IdentitySources(rest.num_vertices());
  result.cell_source.resize(rest.num_cells());
  for (int32_t c = 0; c < rest.num_cells(); ++c) result.cell_source[c] = c;
  auto& cell = result.mesh.cells.emplace_back();
  cell.push_back(bottom);
  cell.push_back(top);
  for (int32_t i = 0; i < k; ++i) {
    const int32_t j = (i + 1) % k;
    cell.push_back({a[i], a[j], top[j], top[i]});
  }
  result.cell_source.push_back(-1);

  int32_t num_components = 0;
  const std::vector<int32_t> comp = internal::CellComponents(rest, &num_components);
  const bool joined = comp[rest.face_cells(face_a)[0]] != comp[rest.face_cells(face_b)[0]];
  const int64_t euler_before = rest.CountBoundary().euler();
  ASSIGN_OR_RETURN(EditResult done,
                   internal::Finish("merge", std::move(result), internal::SharpPairs(rest, sharp)));
  ASSIGN_OR_RETURN(const mesh::CellComplex merged, mesh::CellComplex::FromInput(done.mesh));
  const int64_t euler_after = merged.CountBoundary().euler();
  done.summary =
      absl::StrCat("merged faces ", face_a, " and ", face_b, " (", k, " vertices) with 1 cell: ",
                   joined                       ? "joined two components"
                   : euler_after < euler_before ? "made a handle"
                                                : "filled a gap within one component",
                   "; boundary Euler characteristic ", euler_before, " -> ", euler_after);
  return done;
}

}  // namespace dynsolid::sculpt
