// Drags and curve manipulation (the paper's pull/push and Fig. 9a): springs
// from material points to targets a client moves. They are follower loads
// (solid_loads.cc PressureForces adds them): evaluated at every force
// evaluation, their work counted trapezoidally in the energy ledger.
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/scene/scene_loader.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

constexpr int kMaxCurvePoints = 256;
constexpr int kDefaultCurveSamples = 16;

absl::Status CheckStiffness(double k, std::string_view field) {
  if (!(k > 0) || k > Solid::kMaxDragStiffness) {
    return absl::InvalidArgumentError(absl::StrCat(A(field), ".stiffness must be in (0, ",
                                                   Solid::kMaxDragStiffness, "] N/m, got ", k));
  }
  return absl::OkStatus();
}

// Points at arc-length fractions 0, 1/(n-1), ..., 1 of a polyline.
std::vector<Eigen::Vector3d> Resample(const std::vector<Eigen::Vector3d>& line, int n) {
  std::vector<double> len(line.size(), 0.0);
  for (size_t i = 1; i < line.size(); ++i) len[i] = len[i - 1] + (line[i] - line[i - 1]).norm();
  std::vector<Eigen::Vector3d> out;
  out.reserve(n);
  const double total = len.back();
  size_t seg = 1;
  for (int k = 0; k < n; ++k) {
    const double s = total * k / (n - 1);
    while (seg + 1 < line.size() && len[seg] < s) ++seg;
    const double a = len[seg - 1], b = len[seg];
    const double t = b > a ? std::clamp((s - a) / (b - a), 0.0, 1.0) : 0.0;
    out.push_back((1 - t) * line[seg - 1] + t * line[seg]);
  }
  return out;
}

std::vector<Eigen::Vector3d> Points3(const google::protobuf::RepeatedPtrField<Vec3>& v) {
  std::vector<Eigen::Vector3d> out;
  for (const Vec3& x : v) out.push_back(V(x));
  return out;
}

}  // namespace

absl::StatusOr<Solid::Impl::ControlWeights> Solid::Impl::ControlRow(
    const Eigen::Vector3d& x, const KnownPoints* known) const {
  if (known != nullptr) {
    auto it = known->rows.find(KnownPoints::KeyOf(x));
    if (it != known->rows.end()) return *it->second;
  }
  ASSIGN_OR_RETURN(MaterialLocation at, Locate(x, false));
  return ControlRowAt(at);
}

Solid::Impl::ControlWeights Solid::Impl::ControlRowAt(const MaterialLocation& at) const {
  std::vector<double> shape;
  ShapeAt(at, shape);
  const int32_t* ids = layout->blocks[at.kind].element_nodes(at.element);
  std::map<int32_t, double> w;
  for (size_t k = 0; k < shape.size(); ++k) {
    for (subdivision::SparseMatrix::InnerIterator it(d->node_matrix, ids[k]); it; ++it) {
      w[static_cast<int32_t>(it.col())] += shape[k] * it.value();
    }
  }
  return ControlWeights(w.begin(), w.end());
}

absl::StatusOr<LoadSet::DragLoad> Solid::Impl::MakeDrag(const Drag& d,
                                                            const KnownPoints* known) const {
  RETURN_IF_ERROR(scene::ValidateValues(d, "drag"));
  RETURN_IF_ERROR(CheckStiffness(d.stiffness(), "drag"));
  LoadSet::DragLoad load;
  load.drag = d;
  load.stiffness = d.stiffness();
  load.material = {V(d.material_point())};
  load.targets = {V(d.target())};
  absl::StatusOr<ControlWeights> row = ControlRow(load.material[0], known);
  if (!row.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("drag.material_point: ", row.status().message()));
  }
  load.rows.push_back(*std::move(row));
  return load;
}

absl::StatusOr<LoadSet::DragLoad> Solid::Impl::MakeCurve(const CurveDrag& c,
                                                             const KnownPoints* known) const {
  RETURN_IF_ERROR(scene::ValidateValues(c, "curve"));
  RETURN_IF_ERROR(CheckStiffness(c.stiffness(), "curve"));
  if (c.material_points_size() < 2 || c.material_points_size() > kMaxCurvePoints) {
    return absl::InvalidArgumentError(absl::StrCat("curve.material_points: ",
                                                   c.material_points_size(),
                                                   " points; a curve has 2 to ", kMaxCurvePoints));
  }
  if (c.targets_size() != c.material_points_size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "curve.targets: ", c.targets_size(), " points, but material_points has ",
        c.material_points_size()));
  }
  const int samples = c.samples() == 0 ? kDefaultCurveSamples : c.samples();
  if (samples < 2 || samples > kMaxCurvePoints) {
    return absl::InvalidArgumentError(absl::StrCat("curve.samples must be in 2..",
                                                   kMaxCurvePoints, " (0: ", kDefaultCurveSamples,
                                                   "), got ", c.samples()));
  }
  const std::vector<Eigen::Vector3d> line = Points3(c.material_points());
  double length = 0;
  for (size_t i = 1; i < line.size(); ++i) length += (line[i] - line[i - 1]).norm();
  if (!(length > 0)) {
    return absl::InvalidArgumentError("curve.material_points: the polyline has zero length");
  }
  LoadSet::DragLoad load;
  load.curve = true;
  load.shape = c;
  load.stiffness = c.stiffness();
  load.material = Resample(line, samples);
  load.targets = Resample(Points3(c.targets()), samples);
  for (int s = 0; s < samples; ++s) {
    absl::StatusOr<std::vector<std::pair<int32_t, double>>> row = ControlRow(load.material[s], known);
    if (!row.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("curve.material_points: sample ", s, " of ",
                                                     samples, ": ", row.status().message()));
    }
    load.rows.push_back(*std::move(row));
  }
  return load;
}

absl::StatusOr<int64_t> Solid::AddDrag(const Drag& d) {
  Impl& im = *impl_;
  ASSIGN_OR_RETURN(LoadSet::DragLoad load, im.MakeDrag(d));
  const int64_t id = im.loads.Add(std::move(load));
  im.RebuildPressure();
  im.LoadsChanged();
  return id;
}

absl::StatusOr<int64_t> Solid::AddCurveDrag(const CurveDrag& c) {
  Impl& im = *impl_;
  ASSIGN_OR_RETURN(LoadSet::DragLoad load, im.MakeCurve(c));
  const int64_t id = im.loads.Add(std::move(load));
  im.RebuildPressure();
  im.LoadsChanged();
  return id;
}

absl::Status Solid::MoveDrag(int64_t id, const std::vector<Eigen::Vector3d>& targets) {
  Impl& im = *impl_;
  LoadSet::DragLoad* it = im.loads.FindDrag(id);
  if (it == nullptr) {
    return absl::NotFoundError(absl::StrCat("move_drag.load_id: no drag or curve ", id));
  }
  for (size_t i = 0; i < targets.size(); ++i) {
    if (!targets[i].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("move_drag.targets[", i, "] must be finite"));
    }
  }
  if (!it->curve) {
    if (targets.size() != 1) {
      return absl::InvalidArgumentError(absl::StrCat(
          "move_drag: drag ", id, " takes one target, got ", targets.size()));
    }
    it->targets[0] = targets[0];
    it->drag.mutable_target()->set_x(targets[0].x());
    it->drag.mutable_target()->set_y(targets[0].y());
    it->drag.mutable_target()->set_z(targets[0].z());
  } else {
    if (static_cast<int>(targets.size()) != it->shape.material_points_size()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "move_drag.targets: curve ", id, " takes ", it->shape.material_points_size(),
          " points, got ", targets.size()));
    }
    it->targets = Resample(targets, static_cast<int>(it->rows.size()));
    for (size_t i = 0; i < targets.size(); ++i) {
      Vec3* t = it->shape.mutable_targets(static_cast<int>(i));
      t->set_x(targets[i].x());
      t->set_y(targets[i].y());
      t->set_z(targets[i].z());
    }
  }
  im.LoadsChanged();
  return absl::OkStatus();
}

absl::StatusOr<std::vector<Eigen::Vector3d>> Solid::MaterialPositions(
    const std::vector<Eigen::Vector3d>& rest) const {
  std::vector<Eigen::Vector3d> out;
  for (size_t k = 0; k < rest.size(); ++k) {
    absl::StatusOr<std::vector<std::pair<int32_t, double>>> row = impl_->ControlRow(rest[k]);
    if (!row.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("points[", k, "]: ", row.status().message()));
    }
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (const auto& [i, w] : *row) x += w * p_.row(i).transpose();
    out.push_back(x);
  }
  return out;
}

}  // namespace dynsolid::solid
