#include "solver/contact/obstacle_contact.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>

#include "absl/strings/str_cat.h"

namespace dynsolid::contact {
namespace {

inline absl::string_view A(std::string_view s) { return absl::string_view(s.data(), s.size()); }
inline Eigen::Vector3d V(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// The default damping ratio of the normal spring (scene.proto Environment).
constexpr double kDefaultDampingRatio = 0.5;
// The default stiffness (scene.proto Environment.stiffness), times E / L;
// the contact's highest
// frequency times the sub-step at most kStepFrequency; the margin on the
// power iteration's estimate (it converges from below).
constexpr double kDefaultStiffness = 10;
constexpr double kStepFrequency = 0.6;
constexpr double kEstimateMargin = 1.25;
// A touch ends when its vertex is this far (times the vertex spacing) above
// the plane it entered by.
constexpr double kReleaseBand = 0.01;
constexpr int kPowerIterations = 60;
constexpr char kStateMagic[4] = {'E', 'N', 'V', '1'};

absl::Status CheckVec(const Vec3& v, const std::string& field) {
  if (!std::isfinite(v.x()) || !std::isfinite(v.y()) || !std::isfinite(v.z())) {
    return absl::InvalidArgumentError(absl::StrCat(field, " must be finite, got (", v.x(), ", ",
                                                   v.y(), ", ", v.z(), ")"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ObstacleContact::Validate(const Environment& env, std::string_view field) {
  const std::string f(field);
  if (env.has_floor()) {
    if (absl::Status s = CheckVec(env.floor().point(), f + ".floor.point"); !s.ok()) return s;
    if (absl::Status s = CheckVec(env.floor().normal(), f + ".floor.normal"); !s.ok()) return s;
    if (V(env.floor().normal()).norm() == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(f, ".floor.normal must not be zero: it points up, out of the floor"));
    }
  }
  for (int i = 0; i < env.obstacles_size(); ++i) {
    const dynsolid::Obstacle& o = env.obstacles(i);
    const std::string name = absl::StrCat(f, ".obstacles[", i, "]");
    switch (o.shape_case()) {
      case dynsolid::Obstacle::kBox: {
        if (absl::Status s = CheckVec(o.box().min(), name + ".box.min"); !s.ok()) return s;
        if (absl::Status s = CheckVec(o.box().max(), name + ".box.max"); !s.ok()) return s;
        if (!(V(o.box().min()).array() < V(o.box().max()).array()).all()) {
          return absl::InvalidArgumentError(
              absl::StrCat(name, ".box must have min < max on every axis"));
        }
        break;
      }
      case dynsolid::Obstacle::kSphere:
        if (absl::Status s = CheckVec(o.sphere().center(), name + ".sphere.center"); !s.ok()) {
          return s;
        }
        if (!(o.sphere().radius() > 0 && std::isfinite(o.sphere().radius()))) {
          return absl::InvalidArgumentError(absl::StrCat(name, ".sphere.radius must be > 0 metres, got ",
                                                         o.sphere().radius()));
        }
        break;
      default:
        return absl::InvalidArgumentError(absl::StrCat(name, " has no shape: give a box or a sphere"));
    }
  }
  if (!(env.friction() >= 0 && std::isfinite(env.friction()))) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".friction must be >= 0 (0: frictionless), got ", env.friction()));
  }
  if (!(env.stiffness() >= 0 && std::isfinite(env.stiffness()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".stiffness must be >= 0 (a multiple of E / L; 0: the default ", kDefaultStiffness,
        "), got ", env.stiffness()));
  }
  if (!(env.damping_ratio() >= 0 && env.damping_ratio() <= 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".damping_ratio must be in [0, 1] (0: the default ", kDefaultDampingRatio, "), got ",
        env.damping_ratio()));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<ObstacleContact>> ObstacleContact::Create(
    const Environment& env, const SurfaceInput& surface) {
  if (absl::Status s = Validate(env, "environment"); !s.ok()) return s;
  if (!env.has_floor() && env.obstacles_size() == 0) return std::unique_ptr<ObstacleContact>();
  std::unique_ptr<ObstacleContact> c(new ObstacleContact());
  if (env.has_floor()) {
    Shape o;
    o.kind = Shape::kPlane;
    o.a = V(env.floor().point());
    o.b = V(env.floor().normal()).normalized();
    c->obstacles_.push_back(o);
  }
  for (const dynsolid::Obstacle& in : env.obstacles()) {
    Shape o;
    if (in.has_box()) {
      o.kind = Shape::kBox;
      o.a = V(in.box().min());
      o.b = V(in.box().max());
    } else {
      o.kind = Shape::kSphere;
      o.a = V(in.sphere().center());
      o.radius = in.sphere().radius();
    }
    c->obstacles_.push_back(o);
  }
  c->friction_ = env.friction();
  c->damping_ratio_ = env.damping_ratio() > 0 ? env.damping_ratio() : kDefaultDampingRatio;
  c->stiffness_ = env.stiffness() > 0 ? env.stiffness() : kDefaultStiffness;
  c->BuildGroups(surface);
  return c;
}

void ObstacleContact::BuildGroups(const SurfaceInput& s) {
  const auto& rows = *s.rows;
  const int64_t nv = rows.rows();
  controls_ = rows.cols();
  row_start_.assign(1, 0);
  row_col_.clear();
  row_val_.clear();
  for (int64_t v = 0; v < nv; ++v) {
    double sum = 0;
    for (Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>::InnerIterator it(rows, v); it;
         ++it) {
      row_col_.push_back(static_cast<int32_t>(it.col()));
      row_val_.push_back(it.value());
      sum += it.value();
      if (it.value() < 0) convex_rows_ = false;
    }
    if (std::abs(sum - 1.0) > 1e-9) convex_rows_ = false;
    row_start_.push_back(static_cast<int64_t>(row_col_.size()));
  }
  // The solid's size: the largest side of its rest surface's box.
  if (nv > 0) extent_ = (s.rest->colwise().maxCoeff() - s.rest->colwise().minCoeff()).maxCoeff();
  // Areas: a quarter of each quad's (a triangle's third to each corner).
  area_.assign(nv, 0.0);
  std::vector<int32_t> vertex_group(nv, -1);
  int32_t groups = 0;
  for (size_t q = 0; q < s.quads->size(); ++q) {
    const std::array<int32_t, 4>& v = (*s.quads)[q];
    const Eigen::Vector3d x0 = s.rest->row(v[0]).transpose(), x1 = s.rest->row(v[1]).transpose(),
                          x2 = s.rest->row(v[2]).transpose(), x3 = s.rest->row(v[3]).transpose();
    const double area = 0.5 * ((x2 - x0).cross(x3 - x1)).norm();
    const bool triangle = v[2] == v[3];
    for (int k = 0; k < (triangle ? 3 : 4); ++k) area_[v[k]] += area / (triangle ? 3 : 4);
    const int32_t g = (*s.quad_group)[q];
    groups = std::max(groups, g + 1);
    for (int k = 0; k < 4; ++k) {
      if (vertex_group[v[k]] < 0) vertex_group[v[k]] = g;
    }
  }
  // Vertices no quad names (none on a closed surface) go to a group of their own.
  for (int64_t v = 0; v < nv; ++v) {
    if (vertex_group[v] < 0) vertex_group[v] = groups;
  }
  ++groups;
  std::vector<std::vector<int32_t>> members(groups);
  for (int64_t v = 0; v < nv; ++v) members[vertex_group[v]].push_back(static_cast<int32_t>(v));
  group_vertex_start_.assign(1, 0);
  group_point_start_.assign(1, 0);
  group_vertex_.clear();
  group_point_.clear();
  std::vector<int32_t> points;
  for (const std::vector<int32_t>& m : members) {
    if (m.empty()) continue;
    points.clear();
    for (int32_t v : m) {
      group_vertex_.push_back(v);
      for (int64_t k = row_start_[v]; k < row_start_[v + 1]; ++k) points.push_back(row_col_[k]);
    }
    std::sort(points.begin(), points.end());
    points.erase(std::unique(points.begin(), points.end()), points.end());
    group_point_.insert(group_point_.end(), points.begin(), points.end());
    group_vertex_start_.push_back(static_cast<int64_t>(group_vertex_.size()));
    group_point_start_.push_back(static_cast<int64_t>(group_point_.size()));
  }
  seen_.assign(static_cast<size_t>(nv) * obstacles_.size(), 0);
}

int ObstacleContact::Calibrate(const Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>& mt_rows,
                               double young, double h, int substeps, int max_substeps) {
  const Eigen::SparseMatrix<double> mt = mt_rows;
  const int64_t nc = controls_;
  const int64_t nv = static_cast<int64_t>(area_.size());
  // Each vertex's share of stiffness, shaped by the mass behind it: the
  // least, over the control points its row names, of the point's (lumped)
  // mass over the weight all vertices lean on it with. Then the contact
  // frequency is about the same everywhere, and no light corner limits
  // the rest (header: the Gershgorin bound of the lumped system).
  std::vector<double> lumped(nc, 0.0), lean(nc, 0.0);
  for (int64_t i = 0; i < nc; ++i) {
    for (Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>::InnerIterator it(mt_rows, i); it; ++it) {
      lumped[i] += it.value();
    }
  }
  for (int64_t k = 0; k < static_cast<int64_t>(row_col_.size()); ++k) lean[row_col_[k]] += std::abs(row_val_[k]);
  weight_.assign(nv, 0.0);
  double total_area = 0, total_weight = 0;
  std::vector<Eigen::Triplet<double>> t;
  for (int64_t v = 0; v < nv; ++v) {
    double w = INFINITY;
    for (int64_t i = row_start_[v]; i < row_start_[v + 1]; ++i) {
      const int32_t c = row_col_[i];
      if (lean[c] > 0) w = std::min(w, std::max(0.0, lumped[c]) / lean[c]);
    }
    weight_[v] = std::isfinite(w) ? w : 0.0;
    total_area += area_[v];
    total_weight += weight_[v];
    for (int64_t i = row_start_[v]; i < row_start_[v + 1]; ++i) {
      for (int64_t j = row_start_[v]; j < row_start_[v + 1]; ++j) {
        t.emplace_back(row_col_[i], row_col_[j], weight_[v] * row_val_[i] * row_val_[j]);
      }
    }
  }
  spacing_ = nv > 0 ? std::sqrt(total_area / static_cast<double>(nv)) : 0.0;
  release_ = kReleaseBand * spacing_;
  // K1 = S^T diag(w) S: the contact stiffness per unit scale with every
  // vertex in contact along one axis; lambda its largest frequency squared
  // against Mt (power iteration, from below: times a margin).
  Eigen::SparseMatrix<double> k1(nc, nc);
  k1.setFromTriplets(t.begin(), t.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> mass(mt);
  Eigen::VectorXd x(nc);
  for (int64_t i = 0; i < nc; ++i) {
    // A fixed start with every frequency in it (no symmetry to miss).
    const uint64_t bits = (static_cast<uint64_t>(i) + 1) * 0x9E3779B97F4A7C15ull;
    x[i] = 0.5 + static_cast<double>(bits >> 11) / 9007199254740992.0;
  }
  double lambda = 0;
  for (int it = 0; it < kPowerIterations && mass.info() == Eigen::Success; ++it) {
    const Eigen::VectorXd kx = k1 * x;
    const double m_norm = x.dot(mt * x);
    if (!(m_norm > 0)) break;
    lambda = x.dot(kx) / m_norm;
    x = mass.solve(kx);
    const double n = x.norm();
    if (!(n > 0) || !std::isfinite(n)) break;
    x /= n;
  }
  lambda *= kEstimateMargin;
  min_substeps_ = 1;
  scale_ = 0;
  omega_ = 0;
  kappa_ = 0;
  if (!(lambda > 0) || !(total_weight > 0) || !(extent_ > 0) || !(young > 0)) return min_substeps_;
  // The stiffest the sub-step allows: omega_c h_sub = kStepFrequency. The
  // sub-steps rise (from the solid's own) only when that is below the
  // target kStiffnessFactor E / L per square metre, summed over the surface.
  const double target = stiffness_ * young / extent_ * total_area;
  const double needed = std::ceil(h * std::sqrt(lambda * target / total_weight) / kStepFrequency);
  min_substeps_ = static_cast<int>(
      std::clamp(std::max(needed, static_cast<double>(substeps)), 1.0, static_cast<double>(max_substeps)));
  omega_ = kStepFrequency * min_substeps_ / h;
  scale_ = omega_ * omega_ / lambda;
  kappa_ = scale_ * total_weight / total_area;
  return min_substeps_;
}

Eigen::Vector3d ObstacleContact::VertexAt(int32_t v, const Points& p) const {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int64_t k = row_start_[v]; k < row_start_[v + 1]; ++k) {
    x += row_val_[k] * p.row(row_col_[k]).transpose();
  }
  return x;
}

void ObstacleContact::GroupBox(int32_t g, const Points& p, const Points& prev,
                               Eigen::Vector3d& lo, Eigen::Vector3d& hi) const {
  lo = Eigen::Vector3d::Constant(INFINITY);
  hi = -lo;
  for (int64_t k = group_point_start_[g]; k < group_point_start_[g + 1]; ++k) {
    const int32_t i = group_point_[k];
    lo = lo.cwiseMin(p.row(i).transpose()).cwiseMin(prev.row(i).transpose());
    hi = hi.cwiseMax(p.row(i).transpose()).cwiseMax(prev.row(i).transpose());
  }
}

bool ObstacleContact::BoxMayTouch(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                                  int32_t o) const {
  if (!convex_rows_) return true;
  const Shape& ob = obstacles_[o];
  switch (ob.kind) {
    case Shape::kPlane: {
      const Eigen::Vector3d c = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
      return ob.b.dot(c - ob.a) - ob.b.cwiseAbs().dot(half) < 0;
    }
    case Shape::kBox:
      return (lo.array() <= ob.b.array()).all() && (hi.array() >= ob.a.array()).all();
    case Shape::kSphere: {
      const Eigen::Vector3d nearest = ob.a.cwiseMax(lo).cwiseMin(hi);
      return (nearest - ob.a).squaredNorm() < ob.radius * ob.radius;
    }
  }
  return true;
}

bool ObstacleContact::Begin(int32_t v, int32_t o, const Eigen::Vector3d& x,
                            const Eigen::Vector3d& x_prev, Touch& t) const {
  const Shape& ob = obstacles_[o];
  t.vertex = v;
  t.obstacle = o;
  const Eigen::Vector3d d = x - x_prev;
  switch (ob.kind) {
    case Shape::kPlane: {
      t.normal = ob.b;
      t.offset = ob.b.dot(ob.a);
      const double s = t.normal.dot(x) - t.offset, s0 = t.normal.dot(x_prev) - t.offset;
      if (s >= 0) return false;
      // Where the path crossed the plane (or, starting below, straight above x).
      t.anchor = s0 > 0 ? Eigen::Vector3d(x_prev + (s0 / (s0 - s)) * d) : Eigen::Vector3d(x - s * t.normal);
      return true;
    }
    case Shape::kBox: {
      const bool inside = (x.array() > ob.a.array()).all() && (x.array() < ob.b.array()).all();
      const bool started_inside =
          (x_prev.array() > ob.a.array()).all() && (x_prev.array() < ob.b.array()).all();
      int axis = -1;
      double side = 0, t_enter = 0;
      if (started_inside) {
        if (!inside) return false;
        // Already inside at the sub-step's start (placed there): the nearest face.
        double best = INFINITY;
        for (int k = 0; k < 3; ++k) {
          if (x[k] - ob.a[k] < best) best = x[k] - ob.a[k], axis = k, side = -1;
          if (ob.b[k] - x[k] < best) best = ob.b[k] - x[k], axis = k, side = 1;
        }
      } else {
        // The slab test along the path x_prev -> x: the face it entered by.
        double t0 = 0, t1 = 1;
        for (int k = 0; k < 3; ++k) {
          if (d[k] == 0) {
            if (x_prev[k] <= ob.a[k] || x_prev[k] >= ob.b[k]) return false;
            continue;
          }
          double ta = (ob.a[k] - x_prev[k]) / d[k], tb = (ob.b[k] - x_prev[k]) / d[k];
          double s = -1;
          if (ta > tb) std::swap(ta, tb), s = 1;
          if (ta > t0) t0 = ta, axis = k, side = s;
          t1 = std::min(t1, tb);
        }
        if (axis < 0 || t0 > t1 || t0 > 1) return false;
        t_enter = t0;
      }
      t.normal = Eigen::Vector3d::Zero();
      t.normal[axis] = side;
      t.offset = side > 0 ? ob.b[axis] : -ob.a[axis];
      const Eigen::Vector3d entry = x_prev + t_enter * d;
      t.anchor = started_inside ? Eigen::Vector3d(x - (t.normal.dot(x) - t.offset) * t.normal)
                                : entry;
      return true;
    }
    case Shape::kSphere: {
      const Eigen::Vector3d r = x - ob.a;
      if (r.squaredNorm() < ob.radius * ob.radius) {
        const double n = r.norm();
        t.normal = n > 0 ? Eigen::Vector3d(r / n) : Eigen::Vector3d::UnitZ();
        t.offset = t.normal.dot(ob.a) + ob.radius;
        t.anchor = ob.a + ob.radius * t.normal;
        return true;
      }
      // Passed through within the sub-step: the first crossing of the path.
      const double a = d.squaredNorm();
      if (a == 0) return false;
      const Eigen::Vector3d r0 = x_prev - ob.a;
      const double b = r0.dot(d), c = r0.squaredNorm() - ob.radius * ob.radius;
      const double disc = b * b - a * c;
      if (c <= 0 || disc <= 0) return false;
      const double s = (-b - std::sqrt(disc)) / a;
      if (s < 0 || s > 1) return false;
      const Eigen::Vector3d entry = x_prev + s * d;
      t.normal = (entry - ob.a).normalized();
      t.offset = t.normal.dot(ob.a) + ob.radius;
      t.anchor = entry;
      return t.normal.dot(x) < t.offset;
    }
  }
  return false;
}

bool ObstacleContact::Holds(Touch& t, const Eigen::Vector3d& x) const {
  const Shape& ob = obstacles_[t.obstacle];
  switch (ob.kind) {
    case Shape::kPlane:
      return t.normal.dot(x) < t.offset + release_;
    case Shape::kBox: {
      if (t.normal.dot(x) >= t.offset + release_) return false;
      // Still over the face it entered by (not slid off its edge).
      for (int k = 0; k < 3; ++k) {
        if (t.normal[k] != 0) continue;
        if (x[k] < ob.a[k] || x[k] > ob.b[k]) return false;
      }
      return true;
    }
    case Shape::kSphere: {
      const Eigen::Vector3d r = x - ob.a;
      if (r.squaredNorm() < ob.radius * ob.radius) {
        const double n = r.norm();
        if (n > 0) t.normal = r / n;
        t.offset = t.normal.dot(ob.a) + ob.radius;
        return true;
      }
      // Passed beyond the centre: held by the plane it entered by while
      // over the ball's disc.
      if (t.normal.dot(x) >= t.offset + release_) return false;
      const Eigen::Vector3d tangent = x - ob.a - t.normal.dot(x - ob.a) * t.normal;
      return tangent.norm() < ob.radius;
    }
  }
  return false;
}

void ObstacleContact::AddForces(const Points& p, const Points& prev, double h, Points& out) {
  const size_t no = obstacles_.size();
  next_.clear();
  for (Touch t : touches_) {
    if (Holds(t, VertexAt(t.vertex, p))) {
      seen_[static_cast<size_t>(t.vertex) * no + t.obstacle] = 1;
      next_.push_back(t);
    }
  }
  const size_t held = next_.size();
  groups_checked_ = 0;
  const int32_t groups = static_cast<int32_t>(group_vertex_start_.size()) - 1;
  Eigen::Vector3d lo, hi;
  for (int32_t g = 0; g < groups; ++g) {
    // The box around the group's control points at the sub-step's start
    // and end (once, for every obstacle).
    if (convex_rows_) GroupBox(g, p, prev, lo, hi);
    for (size_t o = 0; o < no; ++o) {
      if (!BoxMayTouch(lo, hi, static_cast<int32_t>(o))) continue;
      ++groups_checked_;
      for (int64_t k = group_vertex_start_[g]; k < group_vertex_start_[g + 1]; ++k) {
        const int32_t v = group_vertex_[k];
        if (seen_[static_cast<size_t>(v) * no + o]) continue;
        Touch t;
        if (Begin(v, static_cast<int32_t>(o), VertexAt(v, p), VertexAt(v, prev), t)) {
          next_.push_back(t);
        }
      }
    }
  }
  for (size_t k = 0; k < held; ++k) {
    seen_[static_cast<size_t>(next_[k].vertex) * no + next_[k].obstacle] = 0;
  }
  if (next_.size() > held) {
    std::sort(next_.begin(), next_.end(), [](const Touch& a, const Touch& b) {
      return a.vertex != b.vertex ? a.vertex < b.vertex : a.obstacle < b.obstacle;
    });
  }
  max_depth_ = 0;
  const double zeta = damping_ratio_;
  for (Touch& t : next_) {
    const Eigen::Vector3d x = VertexAt(t.vertex, p);
    const Eigen::Vector3d v = (x - VertexAt(t.vertex, prev)) / h;
    const double depth = t.offset - t.normal.dot(x);
    max_depth_ = std::max(max_depth_, depth);
    const double kn = scale_ * weight_[t.vertex];
    const double cn = omega_ > 0 ? 2.0 * zeta * kn / omega_ : 0.0;
    const double vn = t.normal.dot(v);
    // (Within the release band above the plane, depth < 0: no force, but
    // the touch and its anchor are kept, so that a vertex that trembles on
    // the floor does not creep by re-anchoring.)
    const double fn = depth > 0 ? std::max(0.0, kn * depth - cn * vn) : 0.0;
    Eigen::Vector3d f = fn * t.normal;
    const Eigen::Vector3d on_plane = x + depth * t.normal;
    if (friction_ > 0 && kn > 0) {
      // The stick spring to the anchor: past the Coulomb limit the vertex
      // slips and the anchor is dragged along so that the spring carries
      // exactly the limit; below it the spring and the tangential damping
      // act together, capped at the limit (the anchor stays).
      Eigen::Vector3d u = x - t.anchor;
      u -= t.normal.dot(u) * t.normal;
      const double cap = friction_ * fn, un = u.norm();
      Eigen::Vector3d ft;
      if (kn * un > cap) {
        ft = -(cap / un) * u;
        t.anchor = on_plane - (cap / (kn * un)) * u;
      } else {
        ft = -kn * u - cn * (v - vn * t.normal);
        const double size = ft.norm();
        if (size > cap) ft *= cap / size;
        t.anchor -= (t.normal.dot(t.anchor) - t.offset) * t.normal;
      }
      f += ft;
    } else {
      t.anchor = on_plane;
    }
    for (int64_t k = row_start_[t.vertex]; k < row_start_[t.vertex + 1]; ++k) {
      out.row(row_col_[k]) += row_val_[k] * f.transpose();
    }
  }
  touches_.swap(next_);
}

std::string ObstacleContact::SaveState() const {
  std::string out(kStateMagic, 4);
  auto put = [&out](const void* v, size_t n) { out.append(static_cast<const char*>(v), n); };
  const uint64_t n = touches_.size();
  put(&n, sizeof(n));
  for (const Touch& t : touches_) {
    put(&t.vertex, sizeof(t.vertex));
    put(&t.obstacle, sizeof(t.obstacle));
    put(t.normal.data(), 3 * sizeof(double));
    put(&t.offset, sizeof(double));
    put(t.anchor.data(), 3 * sizeof(double));
  }
  return out;
}

absl::Status ObstacleContact::RestoreState(std::string_view bytes) {
  absl::StatusOr<std::vector<Touch>> touches = ParseState(bytes);
  if (!touches.ok()) return touches.status();
  touches_ = *std::move(touches);
  return absl::OkStatus();
}

absl::StatusOr<std::vector<ObstacleContact::Touch>> ObstacleContact::ParseState(
    std::string_view bytes) const {
  constexpr size_t kTouchBytes = 2 * sizeof(int32_t) + 7 * sizeof(double);
  if (bytes.size() < 12 || std::memcmp(bytes.data(), kStateMagic, 4) != 0) {
    return absl::DataLossError("environment state: no contact state header");
  }
  uint64_t n = 0;
  std::memcpy(&n, bytes.data() + 4, sizeof(n));
  if (n > (bytes.size() - 12) / kTouchBytes || bytes.size() != 12 + n * kTouchBytes) {
    return absl::DataLossError(absl::StrCat("environment state: ", bytes.size(),
                                            " bytes do not hold ", n, " contacts"));
  }
  std::vector<Touch> touches(n);
  const char* at = bytes.data() + 12;
  const int64_t nv = static_cast<int64_t>(area_.size());
  for (uint64_t i = 0; i < n; ++i) {
    Touch& t = touches[i];
    std::memcpy(&t.vertex, at, 4);
    std::memcpy(&t.obstacle, at + 4, 4);
    std::memcpy(t.normal.data(), at + 8, 24);
    std::memcpy(&t.offset, at + 32, 8);
    std::memcpy(t.anchor.data(), at + 40, 24);
    at += kTouchBytes;
    if (t.vertex < 0 || t.vertex >= nv || t.obstacle < 0 ||
        t.obstacle >= static_cast<int32_t>(obstacles_.size()) || !t.normal.allFinite() ||
        !std::isfinite(t.offset) || !t.anchor.allFinite()) {
      return absl::DataLossError(absl::StrCat("environment state: contact ", i,
                                              " names vertex ", t.vertex, " and obstacle ",
                                              t.obstacle, " or holds a non-finite value"));
    }
    if (i > 0 && (touches[i - 1].vertex > t.vertex ||
                  (touches[i - 1].vertex == t.vertex && touches[i - 1].obstacle >= t.obstacle))) {
      return absl::DataLossError(absl::StrCat("environment state: contact ", i, " out of order"));
    }
  }
  return touches;
}

}  // namespace dynsolid::contact
