// Haptic contact (docs/model.md 9; solid.h "Haptic contact"): the closest point
// of the boundary surface to a probe, the solid's local response there
// over a horizon tau, and reaction loads at surface material points.
//
// The response W = J_c S^-1 J_c^T, S = Mt / tau^2 + Dt / tau + K, is taken
// on the free control coordinates (fixed control points leave the
// unknowns, as in the integrators). K, its factorization and S's are kept
// in a cache (Impl::ContactCache) rebuilt when the material or the fixed
// set changed (Impl::contact.epoch) or tau changed (S only): a contact
// query then costs three triangular solves.
#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {

// The contact stiffness cache: K on the free coordinates (dense; index
// 3 f + a for free point number f and axis a), its LDL^T (for the static
// answer) and S's for the cached tau.
struct Solid::Impl::ContactCache {
  int64_t epoch = -1;
  std::vector<int32_t> free_index;   // control point -> free number, or -1
  std::vector<int32_t> free_points;  // free number -> control point
  Eigen::MatrixXd k;                 // 3 #free square, N/m
  Eigen::MatrixXd mass, damping;     // #free square (the same on x, y, z)
  Eigen::LDLT<Eigen::MatrixXd> k_ldlt;
  bool k_definite = false;
  double horizon = 0;
  Eigen::LDLT<Eigen::MatrixXd> s_ldlt;
  bool s_ok = false;
};

namespace {

using Clock = std::chrono::steady_clock;

// Closest point to q on triangle (a, b, c) (Ericson, Real-Time Collision
// Detection 5.1.5); returns barycentric weights of b and c.
Eigen::Vector2d ClosestOnTriangle(const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                                  const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = q - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {0, 0};
  const Eigen::Vector3d bp = q - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double den = d1 - d3;
    return {den != 0 ? d1 / den : 0, 0};
  }
  const Eigen::Vector3d cp = q - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double den = d2 - d6;
    return {0, den != 0 ? d2 / den : 0};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double den = (d4 - d3) + (d5 - d6);
    const double w = den != 0 ? (d4 - d3) / den : 0;
    return {1 - w, w};
  }
  const double den = va + vb + vc;
  if (den == 0) return {0, 0};
  return {vb / den, vc / den};
}

struct Corners {
  Eigen::Vector3d x[4];
  bool triangle = false;  // (a, b, c, c)
  Eigen::Vector3d At(double u, double v) const {
    return (1 - u) * (1 - v) * x[0] + u * (1 - v) * x[1] + u * v * x[2] + (1 - u) * v * x[3];
  }
  Eigen::Vector3d Du(double v) const { return (1 - v) * (x[1] - x[0]) + v * (x[2] - x[3]); }
  Eigen::Vector3d Dv(double u) const { return (1 - u) * (x[3] - x[0]) + u * (x[2] - x[1]); }
  Eigen::Vector3d Normal(double u, double v) const {
    Eigen::Vector3d n = triangle ? Eigen::Vector3d((x[1] - x[0]).cross(x[2] - x[0]))
                                 : Eigen::Vector3d(Du(v).cross(Dv(u)));
    if (n.squaredNorm() == 0) {  // a degenerate corner: the diagonals' normal
      n = (x[2] - x[0]).cross(x[3] - x[1]);
    }
    const double len = n.norm();
    return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
  }
};

Corners CornersOf(const std::array<int32_t, 4>& q, const Points& x) {
  Corners c;
  for (int k = 0; k < 4; ++k) c.x[k] = x.row(q[k]).transpose();
  c.triangle = q[2] == q[3];
  return c;
}

// Closest point of a bilinear patch (or triangle) to p: (u, v) and the
// squared distance. Start from the better of the two triangles (0, 1, 2)
// and (0, 2, 3), then projected Gauss-Newton steps on the patch.
Eigen::Vector3d ClosestOnQuad(const Corners& c, const Eigen::Vector3d& p) {
  Eigen::Vector2d uv;
  double best;
  {
    const Eigen::Vector2d w = ClosestOnTriangle(p, c.x[0], c.x[1], c.x[2]);
    // Triangle (0, 1, 2): (u, v) = (w_b + w_c, w_c).
    uv = {w[0] + w[1], w[1]};
    best = (c.At(uv[0], uv[1]) - p).squaredNorm();
  }
  if (c.triangle) {
    // x(u, v) with x3 = x2 is the triangle; (u, v) above covers it.
    return {uv[0], uv[1], best};
  }
  {
    const Eigen::Vector2d w = ClosestOnTriangle(p, c.x[0], c.x[2], c.x[3]);
    // Triangle (0, 2, 3): (u, v) = (w_b, w_b + w_c).
    const Eigen::Vector2d t{w[0], w[0] + w[1]};
    const double d = (c.At(t[0], t[1]) - p).squaredNorm();
    if (d < best) {
      best = d;
      uv = t;
    }
  }
  for (int it = 0; it < 8; ++it) {
    const Eigen::Vector3d r = c.At(uv[0], uv[1]) - p;
    const Eigen::Vector3d xu = c.Du(uv[1]), xv = c.Dv(uv[0]);
    Eigen::Matrix2d jtj;
    jtj << xu.dot(xu), xu.dot(xv), xu.dot(xv), xv.dot(xv);
    const Eigen::Vector2d g{xu.dot(r), xv.dot(r)};
    const double det = jtj.determinant();
    if (!(std::abs(det) > 1e-300)) break;
    Eigen::Vector2d next = uv - jtj.inverse() * g;
    next = next.cwiseMax(0.0).cwiseMin(1.0);
    const double d = (c.At(next[0], next[1]) - p).squaredNorm();
    if (!(d < best)) break;
    const double step = (next - uv).norm();
    best = d;
    uv = next;
    if (step < 1e-12) break;
  }
  return {uv[0], uv[1], best};
}

// The control row of surface point (quad, u, v): sum_k N_k A_(node k),
// ascending by control point.
std::vector<std::pair<int32_t, double>> SurfaceRow(const SparseMatrix& surface_rows,
                                                   const std::array<int32_t, 4>& q, double u,
                                                   double v) {
  const double n[4] = {(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v};
  std::map<int32_t, double> w;
  for (int k = 0; k < 4; ++k) {
    if (n[k] == 0) continue;
    for (SparseMatrix::InnerIterator it(surface_rows, q[k]); it; ++it) {
      w[static_cast<int32_t>(it.col())] += n[k] * it.value();
    }
  }
  return {w.begin(), w.end()};
}

double Ms(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

absl::StatusOr<Solid::SurfacePoint> Solid::ClosestSurfacePoint(const Eigen::Vector3d& x) const {
  if (!x.allFinite()) {
    return absl::InvalidArgumentError(
        absl::StrCat("contact query point (", x.x(), ", ", x.y(), ", ", x.z(), ") must be finite"));
  }
  const Impl& im = *impl_;
  const Points pos = SurfacePositions();
  double best = std::numeric_limits<double>::infinity();
  SurfacePoint out;
  for (size_t qi = 0; qi < surface_.quads.size(); ++qi) {
    const std::array<int32_t, 4>& q = surface_.quads[qi];
    // Cull by the quad's bounding sphere about its first corner.
    const Eigen::Vector3d x0 = pos.row(q[0]).transpose();
    double r2 = 0;
    for (int k = 1; k < 4; ++k) r2 = std::max(r2, (pos.row(q[k]).transpose() - x0).squaredNorm());
    const double lower = std::max(0.0, (x - x0).norm() - std::sqrt(r2));
    if (lower * lower > best) continue;
    const Corners c = CornersOf(q, pos);
    const Eigen::Vector3d uvd = ClosestOnQuad(c, x);
    if (uvd[2] < best) {
      best = uvd[2];
      out.quad = static_cast<int32_t>(qi);
      out.u = uvd[0];
      out.v = uvd[1];
    }
  }
  if (out.quad < 0) return absl::FailedPreconditionError("the solid has no boundary surface");
  const Corners c = CornersOf(surface_.quads[out.quad], pos);
  out.point = c.At(out.u, out.v);
  out.normal = c.Normal(out.u, out.v);
  out.material_point = CornersOf(surface_.quads[out.quad], im.surface_rest).At(out.u, out.v);
  out.distance = (x - out.point).dot(out.normal);
  return out;
}

absl::StatusOr<Solid::SurfacePoint> Solid::SurfacePointAt(int32_t quad, double u, double v) const {
  if (quad < 0 || quad >= static_cast<int32_t>(surface_.quads.size())) {
    return absl::InvalidArgumentError(
        absl::StrCat("surface quad ", quad, " is not in [0, ", surface_.quads.size(), ")"));
  }
  if (!(u >= 0 && u <= 1 && v >= 0 && v <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("surface coordinates (", u, ", ", v, ") must lie in [0, 1]^2"));
  }
  const std::array<int32_t, 4>& q = surface_.quads[quad];
  Points pos(4, 3);
  for (int k = 0; k < 4; ++k) pos.row(k) = impl_->surface_rows.row(q[k]) * p_;
  const std::array<int32_t, 4> local{0, 1, 2, q[2] == q[3] ? 2 : 3};
  SurfacePoint out;
  out.quad = quad;
  out.u = u;
  out.v = v;
  const Corners c = CornersOf(local, pos);
  out.point = c.At(u, v);
  out.normal = c.Normal(u, v);
  out.material_point = CornersOf(q, impl_->surface_rest).At(u, v);
  return out;
}

absl::Status Solid::Impl::BuildContactCache(const ContactInputs& in, ContactCache& cache) {
  // The free coordinates.
  cache.free_index.assign(in.nc, -1);
  cache.free_points.clear();
  for (int32_t i = 0; i < in.nc; ++i) {
    if (in.fixed[i]) continue;
    cache.free_index[i] = static_cast<int32_t>(cache.free_points.size());
    cache.free_points.push_back(i);
  }
  const int64_t nf = static_cast<int64_t>(cache.free_points.size());
  const int64_t n = 3 * nf;
  if (n == 0) return absl::FailedPreconditionError("contact: every control point is fixed");
  if (n > kMaxContactDenseDofs) {
    return absl::FailedPreconditionError(
        absl::StrCat("contact: ", n,
                     " free control coordinates; the contact stiffness is built densely "
                     "for at most ",
                     kMaxContactDenseDofs));
  }
  cache.k.setZero(n, n);
  if (in.triplets) {
    // A^T K A at rest (and the penalty springs), node-major 3 i + a.
    for (const Eigen::Triplet<double, int32_t>& t : in.triplets()) {
      const int32_t ri = cache.free_index[t.row() / 3], ci = cache.free_index[t.col() / 3];
      if (ri < 0 || ci < 0) continue;
      cache.k(3 * ri + t.row() % 3, 3 * ci + t.col() % 3) += t.value();
    }
  } else {
    // Forward differences of the internal control forces (and springs) at
    // the current positions, frames found afresh each time.
    const double eps = 1e-6 * std::max(in.extent, 1e-9);
    const Points g0 = in.forces(in.p);
    Points p = in.p;
    for (int64_t f = 0; f < nf; ++f) {
      const int32_t i = cache.free_points[f];
      for (int a = 0; a < 3; ++a) {
        const double keep = p(i, a);
        p(i, a) = keep + eps;
        const Points g = in.forces(p);
        p(i, a) = keep;
        for (int64_t f2 = 0; f2 < nf; ++f2) {
          const int32_t j = cache.free_points[f2];
          for (int b = 0; b < 3; ++b) cache.k(3 * f2 + b, 3 * f + a) = (g(j, b) - g0(j, b)) / eps;
        }
      }
    }
    for (size_t s = 0; s < in.spring_point.size(); ++s) {
      const int32_t f = cache.free_index[in.spring_point[s]];
      if (f < 0) continue;
      for (int a = 0; a < 3; ++a) cache.k(3 * f + a, 3 * f + a) += in.spring_k[s];
    }
    const Eigen::MatrixXd sym = 0.5 * (cache.k + cache.k.transpose());
    cache.k = sym;
  }
  // Mass and damping on the free points.
  cache.mass.setZero(nf, nf);
  cache.damping.setZero(nf, nf);
  for (int32_t r = 0; r < in.mt.outerSize(); ++r) {
    const int32_t fr = cache.free_index[r];
    if (fr < 0) continue;
    for (SparseMatrix::InnerIterator it(in.mt, r); it; ++it) {
      const int32_t fc = cache.free_index[it.col()];
      if (fc >= 0) cache.mass(fr, fc) += it.value();
    }
    if (in.has_damping) {
      for (SparseMatrix::InnerIterator it(in.dt, r); it; ++it) {
        const int32_t fc = cache.free_index[it.col()];
        if (fc >= 0) cache.damping(fr, fc) += it.value();
      }
    }
  }
  cache.k_ldlt.compute(cache.k);
  cache.k_definite = false;
  if (cache.k_ldlt.info() == Eigen::Success && cache.k_ldlt.isPositive()) {
    const Eigen::VectorXd d = cache.k_ldlt.vectorD();
    cache.k_definite = d.minCoeff() > 1e-10 * d.maxCoeff();
  }
  cache.epoch = in.epoch;
  cache.horizon = 0;
  cache.s_ok = false;
  return absl::OkStatus();
}

Solid::Impl::ContactInputs Solid::Impl::ContactInputsNow(const Points& p) const {
  const Impl& im = *this;
  ContactInputs in;
  in.epoch = im.contact.epoch;
  in.nc = p.rows();
  in.fixed = im.fixed;
  in.mt = im.mt;
  in.dt = im.dt;
  in.has_damping = im.has_damping;
  in.spring_point = im.spring_point;
  in.spring_k = im.spring_k;
  if (im.corotational == nullptr) {
    in.p = p;
    const Eigen::Vector3d ext =
        (im.rest_control.colwise().maxCoeff() - im.rest_control.colwise().minCoeff()).transpose();
    in.extent = ext.maxCoeff();
  }
  return in;
}

int64_t Solid::contact_epoch() const { return impl_->contact.epoch; }

bool Solid::ContactCacheStale() const {
  const Impl& im = *impl_;
  return im.contact.cache == nullptr || im.contact.cache->epoch != im.contact.epoch;
}

class Solid::PreparedContact {
 public:
  const Solid* solid = nullptr;
  std::shared_ptr<Impl::ContactCache> cache;
};

std::function<absl::StatusOr<std::shared_ptr<Solid::PreparedContact>>()> Solid::ContactCacheJob()
    const {
  const Impl& im = *impl_;
  auto in = std::make_shared<Impl::ContactInputs>(im.ContactInputsNow(p_));
  // What the job reads of the solid: kept alive by shared ownership (a paint
  // may replace them meanwhile), and never changed once built.
  std::shared_ptr<const models::ElementLayout> layout = im.layout;
  std::shared_ptr<const models::InternalForceModel> model = im.model;
  const scene::Discretization* dd = &d_;
  const fem::NodeRows* rows = &im.node_rows;
  const bool corotational = im.corotational != nullptr;
  std::shared_ptr<const CellPartials> k0_cells = im.k0_cells;
  return [this, in, layout, model, dd, rows, corotational,
          k0_cells]() -> absl::StatusOr<std::shared_ptr<PreparedContact>> {
    auto out = std::make_shared<PreparedContact>();
    out->solid = this;
    out->cache = std::make_shared<Impl::ContactCache>();
    if (corotational) {
      const auto& corot = static_cast<const models::CorotationalModel&>(*model);
      in->triplets = [&] {
        WorkerPool pool(1);
        return Impl::TripletsOf(Impl::StiffnessSparse(*dd, *layout, corot, in->spring_point,
                                                      in->spring_k, pool, k0_cells.get()));
      };
      RETURN_IF_ERROR(Impl::BuildContactCache(*in, *out->cache));
      return out;
    }
    // The local-frame columns: a model of this job's own on a pool of its
    // own, taking the solid's element matrices over (the same forces).
    WorkerPool pool(1);
    const std::unique_ptr<models::InternalForceModel> own =
        impl_->ModelCopy(*layout, *model, pool);
    in->forces = [&](const Points& p) {
      const Points d = rows->Multiply(p);
      Points g(d.rows(), 3);
      own->ResetFrames();
      own->ExactForces(d, g);
      Points control;
      rows->MultiplyTransposed(g, 0, d.rows(), control);
      return control;
    };
    RETURN_IF_ERROR(Impl::BuildContactCache(*in, *out->cache));
    return out;
  };
}

bool Solid::InstallContactCache(std::shared_ptr<PreparedContact> prepared) {
  Impl& im = *impl_;
  if (prepared == nullptr || prepared->solid != this ||
      prepared->cache->epoch != im.contact.epoch) {
    return false;
  }
  im.contact.cache = std::move(prepared->cache);
  return true;
}

absl::StatusOr<Solid::ContactResponse> Solid::ContactResponseAt(const SurfacePoint& c,
                                                                double horizon,
                                                                bool build_if_stale) {
  Impl& im = *impl_;
  if (!(horizon >= 1e-4 && horizon <= 100)) {
    return absl::InvalidArgumentError(
        absl::StrCat("contact horizon must be in [1e-4, 100] s, got ", horizon));
  }
  if (c.quad < 0 || c.quad >= static_cast<int32_t>(surface_.quads.size()) ||
      !(c.u >= 0 && c.u <= 1 && c.v >= 0 && c.v <= 1) || !c.normal.allFinite() ||
      std::abs(c.normal.norm() - 1) > 1e-6) {
    return absl::InvalidArgumentError("contact point: bad quad, (u, v) or normal");
  }
  ContactResponse out;
  out.horizon = horizon;
  const auto t_build = Clock::now();
  if (ContactCacheStale()) {
    if (!build_if_stale) {
      return absl::UnavailableError("contact: the contact stiffness is being built");
    }
    auto cache = std::make_shared<Impl::ContactCache>();
    Impl::ContactInputs in = im.ContactInputsNow(p_);
    if (im.corotational != nullptr) {
      in.triplets = [&im] { return im.StiffnessTriplets(); };
    } else {
      in.forces = [this](const Points& p) { return InternalControlForces(p); };
    }
    RETURN_IF_ERROR(Impl::BuildContactCache(in, *cache));
    im.contact.cache = std::move(cache);
  }
  Impl::ContactCache& cache = *im.contact.cache;
  const int64_t nf = static_cast<int64_t>(cache.free_points.size());
  const int64_t n = 3 * nf;
  if (cache.horizon != horizon) {
    Eigen::MatrixXd s = cache.k;
    for (int64_t r = 0; r < nf; ++r) {
      for (int64_t col = 0; col < nf; ++col) {
        const double m = cache.mass(r, col) / (horizon * horizon) + cache.damping(r, col) / horizon;
        if (m == 0) continue;
        for (int a = 0; a < 3; ++a) s(3 * r + a, 3 * col + a) += m;
      }
    }
    cache.s_ldlt.compute(s);
    cache.s_ok = cache.s_ldlt.info() == Eigen::Success && cache.s_ldlt.isPositive();
    cache.horizon = horizon;
  }
  out.build_ms = Ms(t_build);
  if (!cache.s_ok) {
    return absl::FailedPreconditionError(
        "contact: S = Mt / tau^2 + Dt / tau + K is not positive definite here");
  }

  // J_c^T e_a on the free coordinates.
  const std::vector<std::pair<int32_t, double>> row =
      SurfaceRow(im.surface_rows, surface_.quads[c.quad], c.u, c.v);
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, 3);
  for (const auto& [i, w] : row) {
    const int32_t f = cache.free_index[i];
    if (f < 0) continue;
    for (int a = 0; a < 3; ++a) rhs(3 * f + a, a) = w;
  }
  const Eigen::MatrixXd u = cache.s_ldlt.solve(rhs);  // n x 3
  out.compliance = rhs.transpose() * u;
  out.compliance = 0.5 * (out.compliance + out.compliance.transpose()).eval();
  const Eigen::Vector3d nrm = c.normal;
  const double wn = nrm.dot(out.compliance * nrm);
  if (!(wn > 0)) {
    return absl::FailedPreconditionError(
        "contact: the contact point does not move (it is held by fixed control points)");
  }
  out.stiffness = 1.0 / wn;
  // Ritz split over u_bar = k S^-1 J^T n (a unit normal displacement).
  const Eigen::VectorXd ubar = out.stiffness * (u * nrm);
  const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> ub(ubar.data(),
                                                                                       nf, 3);
  for (int a = 0; a < 3; ++a) {
    out.mass += ub.col(a).dot(cache.mass * ub.col(a));
    out.damping += ub.col(a).dot(cache.damping * ub.col(a));
  }
  out.elastic = ubar.dot(cache.k * ubar);
  if (cache.k_definite) {
    const Eigen::VectorXd us = cache.k_ldlt.solve(rhs * nrm);
    const double ws = (rhs * nrm).dot(us);
    out.static_stiffness = ws > 0 ? 1.0 / ws : 0.0;
  }
  // The material point's velocity (the last sub-step's).
  for (const auto& [i, w] : row) {
    out.velocity += w * (p_.row(i) - p_prev_.row(i)).transpose() / im.h_sub;
  }
  return out;
}

absl::Status Solid::SetContactLoads(const std::vector<ContactLoad>& loads) {
  Impl& im = *impl_;
  for (size_t k = 0; k < loads.size(); ++k) {
    const ContactLoad& l = loads[k];
    if (l.quad < 0 || l.quad >= static_cast<int32_t>(surface_.quads.size())) {
      return absl::InvalidArgumentError(absl::StrCat("contact load ", k, ": surface quad ", l.quad,
                                                     " is not in [0, ", surface_.quads.size(),
                                                     ")"));
    }
    if (!(l.u >= 0 && l.u <= 1 && l.v >= 0 && l.v <= 1)) {
      return absl::InvalidArgumentError(absl::StrCat("contact load ", k, ": (u, v) = (", l.u, ", ",
                                                     l.v, ") must lie in [0, 1]^2"));
    }
    if (!l.force.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("contact load ", k, ": force must be finite"));
    }
  }
  std::vector<ProbeLoads::Load> weighted;
  weighted.reserve(loads.size());
  for (const ContactLoad& l : loads) {
    if (l.force.squaredNorm() == 0) continue;  // touches nothing: no control row needed
    weighted.emplace_back(SurfaceRow(im.surface_rows, surface_.quads[l.quad], l.u, l.v), l.force);
  }
  const int64_t nc = p_.rows();
  im.probe.Set(nc, weighted, im.forces_valid && im.f.rows() == nc ? &im.f : nullptr);
  return absl::OkStatus();
}

bool Solid::has_contact_loads() const { return impl_->probe.active(); }

}  // namespace dynsolid::solid
