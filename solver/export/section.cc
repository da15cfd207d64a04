#include "solver/export/section.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include <Eigen/SVD>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/common/status_macros.h"

namespace dynsolid::exporter {
namespace {

enum class Field { kStrain, kDisplacement, kStiffness, kDistortion };

// Each cell's value of a per-cell field.
std::vector<double> CellValues(Field field, const mesh::CellComplex& fine, const Points& x,
                               const Points& x0, const scene::Discretization& d,
                               const MaterialFields* materials) {
  const int32_t nc = fine.num_cells();
  std::vector<double> out(nc, 0.0);
  if (field == Field::kStiffness) {
    std::vector<int32_t> count(nc, 0);
    const fem::ElementSet& el = d.elements;
    size_t e = 0;
    for (const std::vector<int32_t>* cells : {&el.cubic_cell, &el.linear_cell, &el.pyramid_cell}) {
      for (int32_t c : *cells) {
        if (e < materials->young.size() && c >= 0 && c < nc) {
          out[c] += materials->young[e];
          ++count[c];
        }
        ++e;
      }
    }
    for (int32_t c = 0; c < nc; ++c) {
      if (count[c] > 0) out[c] /= count[c];
    }
    return out;
  }
  for (int32_t c = 0; c < nc; ++c) {
    const auto v = fine.cell_vertices(c);
    if (field == Field::kStrain) {
      double worst = 0;
      for (size_t i = 0; i < v.size(); ++i) {
        for (size_t j = i + 1; j < v.size(); ++j) {
          const double l0 = (x0.row(v[i]) - x0.row(v[j])).norm();
          if (l0 > 0) worst = std::max(worst, std::abs((x.row(v[i]) - x.row(v[j])).norm() / l0 - 1));
        }
      }
      out[c] = worst;
    } else if (field == Field::kDistortion) {
      // F = (x X^T)(X X^T)^-1 over the vertices about their centroids.
      Eigen::RowVector3d cx = Eigen::RowVector3d::Zero(), cX = Eigen::RowVector3d::Zero();
      for (int32_t i : v) {
        cx += x.row(i);
        cX += x0.row(i);
      }
      cx /= static_cast<double>(v.size());
      cX /= static_cast<double>(v.size());
      Eigen::Matrix3d xX = Eigen::Matrix3d::Zero(), XX = Eigen::Matrix3d::Zero();
      for (int32_t i : v) {
        const Eigen::Vector3d a = (x.row(i) - cx).transpose(), b = (x0.row(i) - cX).transpose();
        xX += a * b.transpose();
        XX += b * b.transpose();
      }
      const Eigen::Matrix3d f = xX * XX.inverse();
      const Eigen::Vector3d s = Eigen::JacobiSVD<Eigen::Matrix3d>(f).singularValues();
      out[c] = s[0] > 0 && std::isfinite(s[0]) ? std::clamp(1.0 - s[2] / s[0], 0.0, 1.0) : 1.0;
    }
  }
  return out;
}

}  // namespace

const std::vector<std::string>& SectionFields() {
  static const std::vector<std::string> kFields = {"strain", "displacement", "stiffness",
                                                   "distortion"};
  return kFields;
}

absl::Status CheckSectionField(const std::string& field) {
  const auto& known = SectionFields();
  if (field.empty() || std::find(known.begin(), known.end(), field) != known.end()) {
    return absl::OkStatus();
  }
  return absl::InvalidArgumentError(
      absl::StrCat("field: \"", field, "\" is not one of ", absl::StrJoin(known, ", ")));
}

absl::StatusOr<Section> CutSection(const SectionInput& in, const Eigen::Vector3d& point,
                                   const Eigen::Vector3d& normal, const std::string& field_name) {
  if (in.discretization == nullptr) return absl::InvalidArgumentError("no discretization");
  if (!point.allFinite()) return absl::InvalidArgumentError("point: not finite");
  const double length = normal.norm();
  if (!std::isfinite(length) || !(length > 0)) {
    return absl::InvalidArgumentError("normal: must be finite and not zero");
  }
  RETURN_IF_ERROR(CheckSectionField(field_name));
  Field field = Field::kStrain;
  std::string unit = "1";
  const std::string name = field_name.empty() ? "strain" : field_name;
  if (name == "displacement") {
    field = Field::kDisplacement, unit = "m";
  } else if (name == "stiffness") {
    field = Field::kStiffness, unit = "Pa";
  } else if (name == "distortion") {
    field = Field::kDistortion, unit = "1";
  }
  if (field == Field::kStiffness && in.materials == nullptr) {
    return absl::InvalidArgumentError("field: stiffness needs the design's materials");
  }
  const scene::Discretization& d = *in.discretization;
  const mesh::CellComplex& fine = d.fine();
  const int64_t nc = d.node_matrix.cols();
  if (in.positions.rows() != nc || in.rest.rows() != nc) {
    return absl::InvalidArgumentError(absl::StrCat("positions: ", in.positions.rows(), " and ",
                                                   in.rest.rows(), " rows for ", nc, " control points"));
  }
  if (!in.positions.allFinite()) return absl::InvalidArgumentError("positions: not finite");
  const Eigen::Vector3d n = normal / length;
  const Points nodes = d.node_matrix * in.positions;
  const Points nodes0 = d.node_matrix * in.rest;
  const Points x = nodes.topRows(fine.num_vertices());
  const Points x0 = nodes0.topRows(fine.num_vertices());
  const std::vector<double> cell_value = CellValues(field, fine, x, x0, d, in.materials);

  Section out;
  out.field = name;
  out.unit = unit;
  struct P {
    Eigen::Vector3d x;
    double v;
    double s;  // signed distance
  };
  auto emit = [&](const P& a, const P& b, const P& c) {
    std::array<const P*, 3> t{&a, &b, &c};
    if ((b.x - a.x).cross(c.x - a.x).dot(n) < 0) std::swap(t[1], t[2]);
    for (const P* p : t) {
      for (int k = 0; k < 3; ++k) out.positions.push_back(static_cast<float>(p->x[k]));
      out.values.push_back(static_cast<float>(p->v));
    }
  };
  auto cross = [](const P& a, const P& b) {
    const double t = a.s / (a.s - b.s);
    return P{a.x + t * (b.x - a.x), a.v + t * (b.v - a.v), 0.0};
  };
  std::vector<int32_t> loop;
  for (int32_t c = 0; c < fine.num_cells(); ++c) {
    const auto verts = fine.cell_vertices(c);
    // Quick reject: all of the cell's vertices on one side.
    bool above = false, below = false;
    for (int32_t i : verts) {
      const double s = n.dot(x.row(i).transpose() - point);
      (s >= 0 ? above : below) = true;
    }
    if (!(above && below)) continue;
    ++out.cells_cut;
    auto make = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& p0) {
      const double v = field == Field::kDisplacement ? (p - p0).norm() : cell_value[c];
      return P{p, v, n.dot(p - point)};
    };
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(), centre0 = Eigen::Vector3d::Zero();
    for (int32_t i : verts) {
      centre += x.row(i).transpose();
      centre0 += x0.row(i).transpose();
    }
    centre /= static_cast<double>(verts.size());
    centre0 /= static_cast<double>(verts.size());
    const P apex = make(centre, centre0);
    const auto faces = fine.cell_faces(c);
    for (int32_t f : faces) {
      const auto fv = fine.face_vertices(f);
      loop.assign(fv.begin(), fv.end());
      for (size_t k = 1; k + 1 < loop.size(); ++k) {
        const std::array<P, 4> tet{
            apex, make(x.row(loop[0]).transpose(), x0.row(loop[0]).transpose()),
            make(x.row(loop[k]).transpose(), x0.row(loop[k]).transpose()),
            make(x.row(loop[k + 1]).transpose(), x0.row(loop[k + 1]).transpose())};
        std::array<int, 4> pos{}, neg{};
        int np = 0, nn = 0;
        for (int i = 0; i < 4; ++i) {
          if (tet[i].s >= 0) {
            pos[np++] = i;
          } else {
            neg[nn++] = i;
          }
        }
        if (np == 0 || nn == 0) continue;
        if (np == 1 || nn == 1) {
          const int lone = np == 1 ? pos[0] : neg[0];
          const std::array<int, 4>& others = np == 1 ? neg : pos;
          emit(cross(tet[lone], tet[others[0]]), cross(tet[lone], tet[others[1]]),
               cross(tet[lone], tet[others[2]]));
        } else {
          const P a = cross(tet[pos[0]], tet[neg[0]]), b = cross(tet[pos[0]], tet[neg[1]]);
          const P e = cross(tet[pos[1]], tet[neg[1]]), g = cross(tet[pos[1]], tet[neg[0]]);
          emit(a, b, e);
          emit(a, e, g);
        }
      }
    }
  }
  if (!out.values.empty()) {
    const auto [lo, hi] = std::minmax_element(out.values.begin(), out.values.end());
    out.min = *lo;
    out.max = *hi;
  }
  return out;
}

}  // namespace dynsolid::exporter
