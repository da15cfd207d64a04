#include "solver/models/local_frame.h"

#include <chrono>


#include "solver/models/rotation.h"

namespace dynsolid::models {
namespace {

constexpr int32_t kBatch = 64;

}  // namespace

LocalFrameModel::LocalFrameModel(const ElementLayout& layout, DeformationMeasure measure,
                                 int32_t num_nodes, WorkerPool& pool)
    : layout_(layout), pool_(pool), measure_(std::move(measure)), num_nodes_(num_nodes) {
  fem::NodeMatrixX3 g;
  for (int kind = 0; kind < 3; ++kind) {
    const ElementBlock& block = layout.blocks[kind];
    const fem::KindTable& table = layout.tables[kind];
    const int n = block.nodes;
    k_[kind].resize(block.groups.size());
    for (size_t gi = 0; gi < block.groups.size(); ++gi) {
      const ElementGroup& grp = block.groups[gi];
      const auto& material = layout.materials[grp.material];
      // K_x = sum_q dV [(l + 2m) gx gx^T + m gy gy^T + m gz gz^T] = B_x B_x^T
      // with B_x's columns sqrt(dV (l + 2m)) gx, sqrt(dV m) gy, sqrt(dV m) gz.
      std::array<Eigen::MatrixXd, 3> b;
      for (auto& m : b) m.resize(n, 3 * table.points);
      for (int q = 0; q < table.points; ++q) {
        const double det = fem::PhysicalGradients(table.dN(q), grp.rest, n, g);
        const double dv = std::max(det, 0.0) * table.weight[q] * kStiffnessFactor;
        const double lam = material[q].lame_lambda(), mu = material[q].lame_mu();
        for (int axis = 0; axis < 3; ++axis) {
          for (int c = 0; c < 3; ++c) {
            const double coef = std::sqrt(dv * (c == axis ? lam + 2 * mu : mu));
            b[axis].col(3 * q + c) = coef * g.col(c);
          }
        }
      }
      for (int axis = 0; axis < 3; ++axis) {
        k_[kind][gi][axis] = b[axis] * b[axis].transpose();
      }
    }
    frames_[kind].assign(block.size(), Eigen::Quaterniond::Identity());
  }
  work_.resize(kForceParts);
  schedule_ = ScheduleElements(layout, kBatch, kForceParts);
  for (Workspace& w : work_) {
    w.g.setZero(num_nodes_, 3);
    for (Eigen::MatrixXd* m : {&w.dx, &w.dy, &w.dz, &w.yx, &w.yy, &w.yz}) {
      m->resize(fem::kCubicNodes, kBatch);
    }
  }
  delta_.setZero(num_nodes_, 3);
}

void LocalFrameModel::ResetFrames() {
  for (auto& f : frames_) std::fill(f.begin(), f.end(), Eigen::Quaterniond::Identity());
}

void LocalFrameModel::RunBatches(size_t begin, size_t end, const Points& d, Workspace& w) {
  using NodeBlock = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::ColMajor, fem::kCubicNodes, 3>;
  NodeBlock pos, del, loc;
  std::array<Eigen::Matrix3d, kBatch> rot;
  w.g.setZero();
  w.energy = 0;
  for (size_t bi = begin; bi < end; ++bi) {
    const ElementBatch& batch = schedule_.batches[bi];
    const ElementBlock& block = layout_.blocks[batch.kind];
    const ElementGroup& grp = block.groups[batch.group];
    const int n = block.nodes;
    pos.resize(n, 3);
    del.resize(n, 3);
    auto dx = w.dx.topLeftCorner(n, batch.count);
    auto dy = w.dy.topLeftCorner(n, batch.count);
    auto dz = w.dz.topLeftCorner(n, batch.count);
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t e = block.by_group[batch.first + b];
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < n; ++i) {
        pos.row(i) = d.row(ids[i]);
        del.row(i) = delta_.row(ids[i]);
      }
      // Deformation gradient at the centre, then its rotation R_e.
      const Eigen::Matrix3d f = pos.transpose().lazyProduct(grp.centre_gradient);
      Eigen::Quaterniond& q = frames_[batch.kind][e];
      ExtractRotation(f, q);
      rot[b] = q.toRotationMatrix();
      // dhat = R_e^T delta, node by node: rows of delta times R_e.
      loc.noalias() = del.lazyProduct(rot[b]);
      dx.col(b) = loc.col(0);
      dy.col(b) = loc.col(1);
      dz.col(b) = loc.col(2);
    }
    const auto& k = k_[batch.kind][batch.group];
    auto yx = w.yx.topLeftCorner(n, batch.count);
    auto yy = w.yy.topLeftCorner(n, batch.count);
    auto yz = w.yz.topLeftCorner(n, batch.count);
    yx.noalias() = k[0] * dx;
    yy.noalias() = k[1] * dy;
    yz.noalias() = k[2] * dz;
    for (int32_t b = 0; b < batch.count; ++b) {
      w.energy += 0.5 * (dx.col(b).dot(yx.col(b)) + dy.col(b).dot(yy.col(b)) +
                         dz.col(b).dot(yz.col(b)));
    }
    for (int32_t b = 0; b < batch.count; ++b) {
      const int32_t e = block.by_group[batch.first + b];
      const int32_t* ids = block.element_nodes(e);
      // g += R_e (K dhat), node by node: rows of (K dhat) times R_e^T.
      del.col(0) = yx.col(b);
      del.col(1) = yy.col(b);
      del.col(2) = yz.col(b);
      loc.noalias() = del.lazyProduct(rot[b].transpose());
      for (int i = 0; i < n; ++i) w.g.row(ids[i]) += loc.row(i);
    }
  }
}

double LocalFrameModel::Forces(const Points& d, Points& g) {
  // The measure in fixed parts (threads take parts t, t + T, ...), summed
  // in part order.
  const auto t0 = std::chrono::steady_clock::now();
  const int parts = static_cast<int>(work_.size());
  const int threads = pool_.size();
  pool_.Run([&](int t) {
    for (int k = t; k < parts; k += threads) measure_.ApplyPart(d, k, parts, work_[k].delta);
  });
  delta_ = work_[0].delta;
  for (int k = 1; k < parts; ++k) delta_ += work_[k].delta;
  const auto t1 = std::chrono::steady_clock::now();
  // Batches in contiguous chunks per thread, each with its own force
  // buffer, summed in chunk order: the same bits whatever the timing.
  pool_.Run([&](int t) {
    for (int k = t; k < parts; k += threads) {
      RunBatches(schedule_.part_start[k], schedule_.part_start[k + 1], d, work_[k]);
    }
  });
  // y = dE/d delta = sum_e R_e K dhat; the force is its pull-back through
  // the measure: g = (d delta / d d)^T y (the gradient of the energy).
  y_ = work_[0].g;
  double energy = work_[0].energy;
  for (int k = 1; k < parts; ++k) {
    y_ += work_[k].g;
    energy += work_[k].energy;
  }
  const auto t2 = std::chrono::steady_clock::now();
  pool_.Run([&](int t) {
    for (int k = t; k < parts; k += threads) {
      measure_.ApplyTransposePart(d, y_, k, parts, work_[k].delta);
    }
  });
  g = work_[0].delta;
  for (int k = 1; k < parts; ++k) g += work_[k].delta;
  const auto t3 = std::chrono::steady_clock::now();
  // The measure's phase holds both its passes (forward and transpose).
  timing_.measure_ms = std::chrono::duration<double, std::milli>((t1 - t0) + (t3 - t2)).count();
  timing_.elements_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  return energy;
}

int64_t LocalFrameModel::shared_matrix_bytes() const {
  int64_t bytes = 0;
  for (const auto& kind : k_)
    for (const auto& grp : kind)
      for (const auto& m : grp) bytes += static_cast<int64_t>(m.size()) * 8;
  return bytes;
}

int64_t LocalFrameModel::per_element_bytes() const { return PerElementBytes(layout_); }

}  // namespace dynsolid::models
