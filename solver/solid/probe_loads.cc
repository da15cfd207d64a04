#include "solver/solid/probe_loads.h"

#include <algorithm>

namespace dynsolid::solid {

void ProbeLoads::Set(int64_t nc, const std::vector<Load>& loads, Points* carried) {
  if (force_.rows() != nc) force_.setZero(nc, 3);
  // The old loads' rows, to take them out of the carried forces.
  Points old_rows(rows_.size(), 3);
  for (size_t r = 0; r < rows_.size(); ++r) old_rows.row(r) = force_.row(rows_[r]);
  const std::vector<int32_t> old = rows_;
  for (int32_t i : old) force_.row(i).setZero();
  rows_.clear();
  for (const auto& [weights, f] : loads) {
    if (f.squaredNorm() == 0) continue;
    for (const auto& [i, w] : weights) {
      force_.row(i) += w * f.transpose();
      rows_.push_back(i);
    }
  }
  std::sort(rows_.begin(), rows_.end());
  rows_.erase(std::unique(rows_.begin(), rows_.end()), rows_.end());
  if (carried != nullptr) {
    for (size_t r = 0; r < old.size(); ++r) carried->row(old[r]) -= old_rows.row(r);
    for (int32_t i : rows_) carried->row(i) += force_.row(i);
  }
}

double ProbeLoads::Work(const Points& p, const Points& p_next) const {
  double w = 0;
  for (int32_t i : rows_) w += force_.row(i).dot(p_next.row(i) - p.row(i));
  return w;
}

void ProbeLoads::Clear() {
  for (int32_t i : rows_) force_.row(i).setZero();
  rows_.clear();
}

}  // namespace dynsolid::solid
