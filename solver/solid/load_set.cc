#include "solver/solid/load_set.h"

#include <algorithm>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace dynsolid::solid {
namespace {

template <typename T>
int64_t TakeId(std::vector<T>& list, T item, int64_t& next_id) {
  item.id = next_id++;
  list.push_back(std::move(item));
  return list.back().id;
}

template <typename T>
bool Erase(std::vector<T>& list, int64_t id) {
  auto it = std::find_if(list.begin(), list.end(), [id](const T& x) { return x.id == id; });
  if (it == list.end()) return false;
  list.erase(it);
  return true;
}

template <typename T>
std::string IdList(const std::vector<T>& items) {
  if (items.empty()) return "none";
  std::string out;
  for (const T& x : items) absl::StrAppend(&out, out.empty() ? "" : ", ", x.id);
  return out;
}

Eigen::RowVector3d Row(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

LoadSet::LoadSet(Contents c, Points held) : c_(std::move(c)), held_at_(std::move(held)) {
  fix_count_.assign(held_at_.rows(), 0);
  for (const FixConstraint& f : c_.fixes) {
    for (int32_t i : f.points) ++fix_count_[i];
  }
}

std::vector<uint8_t> LoadSet::FixedFlags() const {
  std::vector<uint8_t> out(fix_count_.size());
  for (size_t i = 0; i < out.size(); ++i) out[i] = fix_count_[i] > 0 ? 1 : 0;
  return out;
}

int64_t LoadSet::Add(PointLoad load) { return TakeId(c_.point_loads, std::move(load), c_.next_id); }
int64_t LoadSet::Add(PressureLoad load) { return TakeId(c_.pressures, std::move(load), c_.next_id); }
int64_t LoadSet::Add(DragLoad load) { return TakeId(c_.drags, std::move(load), c_.next_id); }

int64_t LoadSet::AddFix(Region region, std::vector<int32_t> points, const Points& p,
                        std::vector<int32_t>* newly_held) {
  for (int32_t i : points) {
    if (fix_count_[i]++ == 0) {
      held_at_.row(i) = p.row(i);
      if (newly_held != nullptr) newly_held->push_back(i);
    }
  }
  return TakeId(c_.fixes, FixConstraint{0, std::move(region), std::move(points)}, c_.next_id);
}

LoadSet::Kind LoadSet::RemoveLoad(int64_t id) {
  if (Erase(c_.point_loads, id)) return Kind::kPointForce;
  if (Erase(c_.pressures, id)) return Kind::kPressure;
  if (Erase(c_.drags, id)) return Kind::kDrag;
  return Kind::kNone;
}

const LoadSet::FixConstraint* LoadSet::FindFix(int64_t id) const {
  for (const FixConstraint& f : c_.fixes) {
    if (f.id == id) return &f;
  }
  return nullptr;
}

std::vector<int32_t> LoadSet::CountsWithout(int64_t id) const {
  std::vector<int32_t> count = fix_count_;
  if (const FixConstraint* f = FindFix(id)) {
    for (int32_t i : f->points) --count[i];
  }
  return count;
}

bool LoadSet::RemoveFix(int64_t id) {
  const FixConstraint* f = FindFix(id);
  if (f == nullptr) return false;
  for (int32_t i : f->points) --fix_count_[i];
  Erase(c_.fixes, id);
  return true;
}

LoadSet::DragLoad* LoadSet::FindDrag(int64_t id) {
  for (DragLoad& d : c_.drags) {
    if (d.id == id) return &d;
  }
  return nullptr;
}

std::vector<int64_t> LoadSet::LoadIds() const {
  std::vector<int64_t> ids;
  for (const auto& l : c_.point_loads) ids.push_back(l.id);
  for (const auto& l : c_.pressures) ids.push_back(l.id);
  for (const auto& l : c_.drags) ids.push_back(l.id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::vector<int64_t> LoadSet::ConstraintIds() const {
  std::vector<int64_t> ids;
  for (const auto& c : c_.fixes) ids.push_back(c.id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::string LoadSet::DescribeLoadIds() const {
  return absl::StrCat("point forces: ", IdList(c_.point_loads), "; pressures: ",
                      IdList(c_.pressures), "; drags: ", IdList(c_.drags));
}

std::string LoadSet::DescribeConstraintIds() const { return IdList(c_.fixes); }

void LoadSet::RebuildConstantForces(
    int64_t nc, const std::function<ControlWeights(const MaterialLocation&)>& row_at,
    const std::function<const Eigen::VectorXd&()>& gravity_mass) {
  has_constant_ = !c_.point_loads.empty() || has_gravity();
  if (!has_constant_) {
    constant_.resize(0, 3);
    return;
  }
  // f = sum over the loads, in order, of their control rows times their
  // forces (A^T N F, N the shape values at the load's material point): a
  // function of the load list alone, made without touching the solid's
  // other nodes (a point force added or removed holds the loop for this).
  constant_ = Points::Zero(nc, 3);
  for (const PointLoad& load : c_.point_loads) {
    if (load.row == nullptr) load.row = std::make_shared<const ControlWeights>(row_at(load.at));
    const Eigen::RowVector3d force = Row(load.msg.force());
    for (const auto& [c, w] : *load.row) constant_.row(c) += w * force;
  }
  // Body force mu g: f = A^T w g^T with w_i = int mu N_i dV, kept per
  // material by the caller, so that a new force or gravity costs no
  // integration over the solid.
  if (has_gravity()) constant_ += gravity_mass() * c_.gravity.transpose();
}

void LoadSet::AddDragForces(const Points& p, Points& out) const {
  for (const DragLoad& load : c_.drags) {
    for (size_t s = 0; s < load.rows.size(); ++s) {
      Eigen::RowVector3d x = Eigen::RowVector3d::Zero();
      for (const auto& [i, w] : load.rows[s]) x += w * p.row(i);
      const Eigen::RowVector3d f = load.stiffness * (load.targets[s].transpose() - x);
      for (const auto& [i, w] : load.rows[s]) out.row(i) += w * f;
    }
  }
}

LoadSet::KnownPoints::Key LoadSet::KnownPoints::KeyOf(const Eigen::Vector3d& x) {
  Key k;
  std::memcpy(k.data(), x.data(), sizeof(k));
  return k;
}

LoadSet::KnownPoints LoadSet::CurrentPoints() const {
  KnownPoints known;
  for (const PointLoad& l : c_.point_loads) {
    known.forces.emplace(KnownPoints::KeyOf(Row(l.msg.position()).transpose()),
                         std::pair(l.at, l.row));
  }
  for (const DragLoad& d : c_.drags) {
    for (size_t s = 0; s < d.material.size(); ++s) {
      known.rows.emplace(KnownPoints::KeyOf(d.material[s]), &d.rows[s]);
    }
  }
  return known;
}

}  // namespace dynsolid::solid
