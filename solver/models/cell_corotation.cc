#include "solver/models/cell_corotation.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/Dense>
#include <Eigen/SVD>

#include "solver/models/internal_force.h"

namespace dynsolid::models {

namespace {

// The orthogonal polar factor of f with det > 0: Higham's scaled Newton
// iteration X <- (g X + X^-T / g) / 2, g = |det X|^(-1/3) while far, which
// converges quadratically from any nonsingular f; for det f <= 0 (a cell
// turned inside out) the rotation nearest f from its SVD.
Eigen::Matrix3d Polar(const Eigen::Matrix3d& f) {
  const double scale = f.norm();
  const double det = f.determinant();
  if (!(scale > 0) || !(det > 1e-9 * scale * scale * scale)) {
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d u = svd.matrixU();
    const Eigen::Matrix3d v = svd.matrixV();
    if ((u * v.transpose()).determinant() < 0) u.col(2) = -u.col(2);
    return u * v.transpose();
  }
  Eigen::Matrix3d x = f;
  for (int it = 0; it < 40; ++it) {
    const double d = x.determinant();
    const Eigen::Matrix3d inv_t = x.inverse().transpose();
    const double change_before = (x - inv_t).norm();
    Eigen::Matrix3d next;
    if (change_before > 1e-2) {
      const double g = std::cbrt(1.0 / std::abs(d));
      next = 0.5 * (g * x + inv_t / g);
    } else {
      next = 0.5 * (x + inv_t);
    }
    const double step = (next - x).norm();
    x = next;
    if (step <= 1e-15) break;
  }
  return x;
}

}  // namespace

CellCorotation::CellCorotation(std::vector<Cell> cells, const Points& rest, WorkerPool& pool)
    : pool_(&pool) {
  std::map<const Eigen::MatrixXd*, int32_t> index;
  cells_.resize(cells.size());
  std::vector<double> cost(cells.size());
  int max_side = 0;
  for (size_t c = 0; c < cells.size(); ++c) {
    Cell& in = cells[c];
    CellData& out = cells_[c];
    auto [it, fresh] = index.try_emplace(in.k.get(), static_cast<int32_t>(matrices_.size()));
    if (fresh) {
      matrices_.push_back(in.k);
      matrix_bytes_ += static_cast<int64_t>(in.k->size()) * 8;
    }
    out.matrix = it->second;
    out.first = static_cast<int32_t>(support_.size());
    out.size = static_cast<int32_t>(in.support.size());
    max_side = std::max(max_side, 3 * out.size);
    cost[c] = 9.0 * out.size * out.size;
    // Weights: each point's diagonal stiffness in this cell.
    const Eigen::MatrixXd& k = *in.k;
    double total = 0;
    std::vector<double> w(out.size);
    for (int a = 0; a < out.size; ++a) {
      w[a] = k(3 * a, 3 * a) + k(3 * a + 1, 3 * a + 1) + k(3 * a + 2, 3 * a + 2);
      total += w[a];
    }
    if (!(total > 0)) {
      std::fill(w.begin(), w.end(), 1.0);
      total = out.size;
    }
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int a = 0; a < out.size; ++a) {
      w[a] /= total;
      centre += w[a] * rest.row(in.support[a]).transpose();
    }
    for (int a = 0; a < out.size; ++a) {
      const Eigen::Vector3d x = rest.row(in.support[a]).transpose() - centre;
      support_.push_back(in.support[a]);
      weight_.push_back(w[a]);
      rest_local_.insert(rest_local_.end(), {x.x(), x.y(), x.z()});
      const Eigen::Vector3d& g = in.gradient[a];
      gradient_.insert(gradient_.end(), {g.x(), g.y(), g.z()});
    }
  }
  // kForceParts contiguous parts of about equal cost; in each, the cells of
  // one matrix form a batch (in order of first appearance).
  double total = 0;
  for (double x : cost) total += x;
  parts_.assign(kForceParts, {});
  size_t c = 0;
  double done = 0;
  int max_batch = 1;
  for (int part = 0; part < kForceParts; ++part) {
    const double until = total * (part + 1) / kForceParts;
    std::map<int32_t, size_t> batch_of;
    while (c < cells_.size() && (done + 0.5 * cost[c] <= until || part == kForceParts - 1)) {
      auto [it, fresh] = batch_of.try_emplace(cells_[c].matrix, parts_[part].size());
      if (fresh) parts_[part].push_back(Batch{cells_[c].matrix, {}});
      parts_[part][it->second].cells.push_back(static_cast<int32_t>(c));
      done += cost[c];
      ++c;
    }
    for (const Batch& b : parts_[part]) max_batch = std::max(max_batch, static_cast<int>(b.cells.size()));
  }
  // Batches are cut to at most kMaxBatch columns (scratch stays small).
  constexpr int kMaxBatch = 64;
  for (auto& part : parts_) {
    std::vector<Batch> cut;
    for (Batch& b : part) {
      for (size_t i = 0; i < b.cells.size(); i += kMaxBatch) {
        Batch piece{b.matrix, {}};
        piece.cells.assign(b.cells.begin() + i,
                           b.cells.begin() + std::min(b.cells.size(), i + kMaxBatch));
        cut.push_back(std::move(piece));
      }
    }
    part = std::move(cut);
  }
  max_side_ = max_side;
  max_batch_ = std::min(max_batch, kMaxBatch);
  scratch_ = MakeScratch(rest.rows());
  held_.assign(cells_.size(), Eigen::Matrix3d::Identity());
}

std::vector<CellCorotation::Scratch> CellCorotation::MakeScratch(int64_t points) const {
  std::vector<Scratch> scratch(kForceParts);
  for (Scratch& s : scratch) {
    s.f.setZero(points, 3);
    s.u.setZero(max_side_, max_batch_);
    s.y.setZero(max_side_, max_batch_);
    s.frames.resize(max_batch_);
  }
  return scratch;
}

Eigen::Vector3d CellCorotation::CentreOf(const CellData& c, const Points& p) const {
  const int32_t* support = support_.data() + c.first;
  const double* w = weight_.data() + c.first;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int a = 0; a < c.size; ++a) centre += w[a] * p.row(support[a]).transpose();
  return centre;
}

Eigen::Matrix3d CellCorotation::FrameOf(const CellData& c, const Points& p,
                                        Eigen::Vector3d& centre) const {
  const int32_t* support = support_.data() + c.first;
  const double* g = gradient_.data() + 3 * static_cast<int64_t>(c.first);
  centre = CentreOf(c, p);
  Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
  for (int a = 0; a < c.size; ++a) {
    const Eigen::Vector3d x = p.row(support[a]).transpose() - centre;
    f += x * Eigen::RowVector3d(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
  }
  const int32_t cell = static_cast<int32_t>(&c - cells_.data());
  if (const double* offsets = flow_ != nullptr && flow_->plastic(cell) ? flow_->offsets() : nullptr) {
    // Relative to the plastic rest shape: F F_p^-1 (CellFlow).
    const double* u = offsets + 3 * static_cast<int64_t>(c.first);
    Eigen::Matrix3d fp = Eigen::Matrix3d::Identity();
    for (int a = 0; a < c.size; ++a) {
      fp += Eigen::Vector3d(u[3 * a], u[3 * a + 1], u[3 * a + 2]) *
            Eigen::RowVector3d(g[3 * a], g[3 * a + 1], g[3 * a + 2]);
    }
    return Polar(f * fp.inverse());
  }
  return Polar(f);
}

double CellCorotation::Energy(int32_t cell, const double* u) const {
  const CellData& c = cells_[cell];
  const Eigen::MatrixXd& k = *matrices_[c.matrix];
  const Eigen::Map<const Eigen::VectorXd> v(u, 3 * c.size);
  return 0.5 * v.dot(k * v);
}

double CellCorotation::Run(const Points& x, Points& g, Mode mode, std::vector<Scratch>& scratch,
                           std::vector<Eigen::Matrix3d>* held, WorkerPool& pool) const {
  const bool nonlinear = mode != Mode::kLinear && mode != Mode::kRest;
  const double* plastic = nonlinear && flow_ != nullptr ? flow_->offsets() : nullptr;
  const bool flowing = mode == Mode::kHold && flow_ != nullptr && flow_->flowing();
  pool.RunParts(kForceParts, [&](int part) {
    Scratch& s = scratch[part];
    s.energy = 0;
    if (mode == Mode::kFrames) {
      for (const Batch& b : parts_[part]) {
        for (int32_t cell : b.cells) {
          Eigen::Vector3d centre;
          (*held)[cell] = FrameOf(cells_[cell], x, centre);
        }
      }
      return;
    }
    s.f.setZero();
    for (const Batch& b : parts_[part]) {
      const Eigen::MatrixXd& k = *matrices_[b.matrix];
      const int side = static_cast<int>(k.rows());
      const int m = static_cast<int>(b.cells.size());
      for (int j = 0; j < m; ++j) {
        const int32_t cell = b.cells[j];
        const CellData& c = cells_[cell];
        Eigen::Vector3d centre;
        Eigen::Matrix3d& r = s.frames[j];
        if (mode == Mode::kFind || mode == Mode::kHold) {
          r = FrameOf(c, x, centre);
          if (mode == Mode::kHold) (*held)[cell] = r;
        } else if (mode == Mode::kRest) {
          r.setIdentity();
          centre = CentreOf(c, x);
        } else {
          r = (*held)[cell];
          centre = CentreOf(c, x);
        }
        const int32_t* support = support_.data() + c.first;
        const double* rest = rest_local_.data() + 3 * static_cast<int64_t>(c.first);
        const bool linear = mode == Mode::kLinear || mode == Mode::kRest;
        for (int a = 0; a < c.size; ++a) {
          const Eigen::Vector3d local = r.transpose() * (x.row(support[a]).transpose() - centre);
          s.u(3 * a, j) = linear ? local.x() : local.x() - rest[3 * a];
          s.u(3 * a + 1, j) = linear ? local.y() : local.y() - rest[3 * a + 1];
          s.u(3 * a + 2, j) = linear ? local.z() : local.z() - rest[3 * a + 2];
        }
        if (plastic != nullptr && flow_->plastic(cell)) {  // (null when linear)
          const double* up = plastic + 3 * static_cast<int64_t>(c.first);
          for (int e = 0; e < 3 * c.size; ++e) s.u(e, j) -= up[e];
        }
      }
      s.y.topLeftCorner(side, m).noalias() = k * s.u.topLeftCorner(side, m);
      for (int j = 0; j < m; ++j) {
        const CellData& c = cells_[b.cells[j]];
        const int32_t* support = support_.data() + c.first;
        const Eigen::Matrix3d& r = s.frames[j];
        s.energy += 0.5 * s.u.col(j).head(side).dot(s.y.col(j).head(side));
        for (int a = 0; a < c.size; ++a) {
          const Eigen::Vector3d f = r * s.y.col(j).segment<3>(3 * a);
          s.f.row(support[a]) += f.transpose();
        }
        if (flowing && flow_->plastic(b.cells[j])) {
          flow_->Flow(b.cells[j], s.u.col(j).data(), s.y.col(j).data());
        }
      }
    }
  });
  double energy = 0;
  if (mode != Mode::kFrames) {
    g = scratch[0].f;
    energy = scratch[0].energy;
    for (int part = 1; part < kForceParts; ++part) {
      g += scratch[part].f;
      energy += scratch[part].energy;
    }
  }
  return energy;
}

double CellCorotation::Forces(const Points& p, Points& g) {
  return Run(p, g, Mode::kHold, scratch_, &held_, *pool_);
}

double CellCorotation::ForcesAt(const Points& p, Points& g) {
  return Run(p, g, Mode::kFind, scratch_, nullptr, *pool_);
}

void CellCorotation::UpdateFrames(const Points& p) {
  Points unused;
  Run(p, unused, Mode::kFrames, scratch_, &held_, *pool_);
}

double CellCorotation::AffineForces(const Points& x, Points& g) {
  return Run(x, g, Mode::kAffine, scratch_, &held_, *pool_);
}

void CellCorotation::ApplyLinearized(const Points& v, Points& out) {
  Run(v, out, Mode::kLinear, scratch_, &held_, *pool_);
}

void CellCorotation::ApplyRest(const Points& v, Points& out, WorkerPool* pool) const {
  std::vector<Scratch> scratch = MakeScratch(v.rows());
  WorkerPool one(1);
  Run(v, out, Mode::kRest, scratch, nullptr, pool != nullptr ? *pool : one);
}

}  // namespace dynsolid::models
