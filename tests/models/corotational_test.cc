// Corotational linear elasticity (docs/model.md 4b): element matrices, rigid
// motion, the energy and its gradient, the analytic energy of uniform
// strain, the linearization, a slow dense reference path, determinism across
// thread counts and no allocation per step.
#include "solver/models/corotational.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "solver/scene/build.h"
#include "solver/scene/scene_loader.h"
#include "tests/models/model_fixture.h"
#include "tests/testing/status_matchers.h"

// Counts heap allocations while g_count_mallocs is set: malloc and friends of
// this executable forward to glibc's. Not under AddressSanitizer, which
// intercepts malloc itself.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
#define DYNSOLID_COUNT_MALLOCS 1
namespace {
std::atomic<bool> g_count_mallocs{false};
std::atomic<int64_t> g_mallocs{0};
void CountMalloc() {
  if (g_count_mallocs.load(std::memory_order_relaxed)) {
    g_mallocs.fetch_add(1, std::memory_order_relaxed);
  }
}
}  // namespace
extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* malloc(size_t size) {
  CountMalloc();
  return __libc_malloc(size);
}
void* calloc(size_t count, size_t size) {
  CountMalloc();
  return __libc_calloc(count, size);
}
void* realloc(void* p, size_t size) {
  CountMalloc();
  return __libc_realloc(p, size);
}
}
#endif

namespace dynsolid::models {
namespace {

constexpr double kYoung = 1e5, kPoisson = 0.3;

MaterialSampler Uniform() {
  return [](const Eigen::Vector3d&, int32_t) { return MaterialPoint{kYoung, kPoisson, 1000, 0}; };
}

MaterialSampler TwoMaterials() { return test_util::TwoMaterials(kYoung, kPoisson); }

struct Fixture : test_util::MeshFixture {
  std::unique_ptr<WorkerPool> pool;
  std::unique_ptr<CorotationalModel> model;

  int64_t nodes() const { return rest.rows(); }
  // Largest extent of the solid at rest (m).
  double size() const { return (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).maxCoeff(); }
};

std::unique_ptr<Fixture> BuildFrom(const absl::StatusOr<Scene>& scene, int levels,
                                   int threads = 1, const MaterialSampler& sampler = Uniform()) {
  auto f = std::make_unique<Fixture>();
  test_util::BuildMesh(scene, levels, sampler, *f);
  f->pool = std::make_unique<WorkerPool>(threads);
  f->model = std::make_unique<CorotationalModel>(f->layout, f->rest, *f->pool);
  return f;
}

std::unique_ptr<Fixture> Build(const std::string& name, int levels, int threads = 1,
                               const MaterialSampler& sampler = Uniform()) {
  return BuildFrom(scene::BuiltinScene(name), levels, threads, sampler);
}

Eigen::Matrix3d Rotation(double angle, const Eigen::Vector3d& axis) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

// rest moved by x -> r x + c.
Points Rigid(const Points& rest, const Eigen::Matrix3d& r, const Eigen::RowVector3d& c) {
  return (rest * r.transpose()).rowwise() + c;
}

// A smooth deformation of strain about `amplitude`, then rotated and moved.
Points Deformed(const Points& rest, double amplitude, const Eigen::Matrix3d& r) {
  Points p = rest;
  for (int64_t i = 0; i < p.rows(); ++i) {
    const double x = rest(i, 0), y = rest(i, 1), z = rest(i, 2);
    p(i, 0) += amplitude * std::sin(1.1 * x + 0.6 * y + 0.2);
    p(i, 1) += amplitude * std::cos(0.8 * y - 0.7 * z + 0.4 * x);
    p(i, 2) += amplitude * (std::sin(0.9 * z + 0.5 * x) + 0.5 * x * y);
  }
  return Rigid(p, r, Eigen::RowVector3d(0.4, -1.3, 2.1));
}

using test_util::Dot;
using test_util::RandomPoints;

// The node-major rigid modes of rest nodes x (n x 3): three translations,
// then three infinitesimal rotations about the centroid.
Eigen::MatrixXd RigidModes(const fem::NodeMatrixX3& x) {
  const int n = static_cast<int>(x.rows());
  const Eigen::RowVector3d centre = x.colwise().mean();
  Eigen::MatrixXd modes = Eigen::MatrixXd::Zero(3 * n, 6);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d r = (x.row(i) - centre).transpose();
    for (int c = 0; c < 3; ++c) {
      modes(3 * i + c, c) = 1;
      modes.block<3, 1>(3 * i, 3 + c) = Eigen::Vector3d::Unit(c).cross(r);
    }
  }
  return modes;
}

TEST(CorotationalTest, GroupMatricesAreSymmetricWithTheRigidMotionsAsTheirNullSpace) {
  for (const char* name : {"mixed", "block3"}) {
    auto f = Build(name, 2, 1, TwoMaterials());
    // Worst cases over all groups, per kind: zero modes relative to the
    // largest eigenvalue (l[5] / l_max), the first non-zero one (l[6] / l_max),
    // and |K m| / (|K| |m|) over the six rigid modes m.
    for (int kind = 0; kind < 3; ++kind) {
      const ElementBlock& block = f->layout.blocks[kind];
      if (std::string(name) == "mixed") {
        ASSERT_GT(block.groups.size(), 0u) << "kind " << kind;
      }
      double worst_zero = 0, worst_gap = 1, worst_mode = 0;
      for (size_t g = 0; g < block.groups.size(); ++g) {
        const Eigen::MatrixXd& k = f->model->K(kind, static_cast<int32_t>(g));
        ASSERT_EQ(k.rows(), 3 * block.nodes);
        const double scale = k.cwiseAbs().maxCoeff();
        EXPECT_LE((k - k.transpose()).cwiseAbs().maxCoeff(), 1e-12 * scale)
            << name << " kind " << kind << " group " << g << " symmetric";
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(k, Eigen::EigenvaluesOnly);
        const Eigen::VectorXd& l = eig.eigenvalues();
        const double top = l[l.size() - 1];
        worst_zero = std::max(worst_zero, std::max(std::abs(l[0]), std::abs(l[5])) / top);
        worst_gap = std::min(worst_gap, l[6] / top);
        EXPECT_LE(std::max(std::abs(l[0]), std::abs(l[5])), 1e-13 * top)
            << name << " kind " << kind << " group " << g << ": six zero modes";
        EXPECT_GT(l[6], 1e-11 * top)
            << name << " kind " << kind << " group " << g << ": only six zero modes";
        const Eigen::MatrixXd modes = RigidModes(block.groups[g].rest);
        const double knorm = eig.eigenvalues().cwiseAbs().maxCoeff();
        for (int m = 0; m < 6; ++m) {
          const double r = (k * modes.col(m)).norm() / (knorm * modes.col(m).norm());
          worst_mode = std::max(worst_mode, r);
          EXPECT_LE(r, 1e-13) << name << " kind " << kind << " group " << g << " mode " << m;
        }
      }
      std::printf("%s kind %d: %zu groups, |l_0..5| / l_max <= %.2e, l_6 / l_max >= %.2e, "
                  "|K m| / (|K| |m|) <= %.2e\n",
                  name, kind, block.groups.size(), worst_zero, worst_gap, worst_mode);
    }
  }
}

TEST(CorotationalTest, RigidMotionHasZeroForceAndEnergy) {
  for (const char* name : {"mixed", "block3"}) {
    auto f = Build(name, 2);
    Points g;
    // Scale: a 1 % stretch along x.
    Points stretched = f->rest;
    stretched.col(0) *= 1.01;
    const double e_scale = f->model->Forces(stretched, g);
    const double scale = g.norm();
    ASSERT_GT(scale, 0);
    // One call from identity frames (the stretch's) to a rotation of 1.1 rad.
    const Points moved =
        Rigid(f->rest, Rotation(1.1, Eigen::Vector3d(0.3, -1, 0.2)), Eigen::RowVector3d(1, 2, 3));
    const double e = f->model->Forces(moved, g);
    std::printf("%s: rigid |g| / |g(1%% stretch)| = %.2e, E / E(1%% stretch) = %.2e\n", name,
                g.norm() / scale, e / e_scale);
    EXPECT_LT(g.norm(), 1e-10 * scale) << name;
    EXPECT_LT(std::abs(e), 1e-20 * e_scale) << name;
    // After a reset the frames start again from identity.
    f->model->ResetFrames();
    const Points back =
        Rigid(f->rest, Rotation(-0.9, Eigen::Vector3d(1, 0.5, 2)), Eigen::RowVector3d(-4, 0, 1));
    f->model->Forces(back, g);
    EXPECT_LT(g.norm(), 1e-10 * scale) << name << " after ResetFrames";
    EXPECT_EQ(f->model->name(), "corotational");
    EXPECT_EQ(f->model->last_timing().measure_ms, -1);
  }
}

// The slow, obvious reference: per element in double, with the element's own
// rest nodes, the frame from an SVD of the centre deformation gradient and
// the energy density lambda/2 tr(eps)^2 + mu eps:eps of eps = sym(grad u).
double ReferenceForces(const Fixture& f, const Points& d, Points& g) {
  g.setZero(d.rows(), 3);
  double energy = 0;
  fem::NodeMatrixX3 x0, x, grad;
  for (int kind = 0; kind < 3; ++kind) {
    const ElementBlock& block = f.layout.blocks[kind];
    const fem::KindTable& table = f.layout.tables[kind];
    const int n = block.nodes;
    x0.resize(n, 3);
    x.resize(n, 3);
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t* ids = block.element_nodes(e);
      for (int i = 0; i < n; ++i) {
        x0.row(i) = f.rest.row(ids[i]);
        x.row(i) = d.row(ids[i]);
      }
      fem::PhysicalGradients(table.centre_dn.data(), x0, n, grad);
      const Eigen::Matrix3d def = x.transpose() * grad;
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(def, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d r = svd.matrixU() * svd.matrixV().transpose();
      if (r.determinant() < 0) {
        Eigen::Matrix3d u = svd.matrixU();
        u.col(2) *= -1;
        r = u * svd.matrixV().transpose();
      }
      const Eigen::RowVector3d xbar = x.colwise().mean(), x0bar = x0.colwise().mean();
      fem::NodeMatrixX3 u(n, 3);
      for (int i = 0; i < n; ++i) {
        u.row(i) = (x.row(i) - xbar) * r - (x0.row(i) - x0bar);
      }
      const auto& material = f.layout.materials[block.groups[block.group[e]].material];
      for (int q = 0; q < table.points; ++q) {
        const double dv = std::max(fem::PhysicalGradients(table.dN(q), x0, n, grad), 0.0) *
                          table.weight[q];
        const Eigen::Matrix3d h = u.transpose() * grad;  // du_a / dx_b
        const Eigen::Matrix3d eps = 0.5 * (h + h.transpose());
        const double lam = material[q].lame_lambda(), mu = material[q].lame_mu();
        const Eigen::Matrix3d sigma =
            lam * eps.trace() * Eigen::Matrix3d::Identity() + 2 * mu * eps;
        energy += dv * 0.5 * (sigma.array() * eps.array()).sum();
        for (int i = 0; i < n; ++i) {
          g.row(ids[i]) += dv * (r * sigma * grad.row(i).transpose()).transpose();
        }
      }
    }
  }
  return energy;
}

TEST(CorotationalTest, MatchesTheDenseReferenceAtADeformedRotatedState) {
  for (const char* name : {"mixed", "block3"}) {
    auto f = Build(name, 2, 3, TwoMaterials());
    const Points p = Deformed(f->rest, 0.02, Rotation(0.8, Eigen::Vector3d(1, 2, -1)));
    Points g, ref;
    const double e = f->model->Forces(p, g);
    const double e_ref = ReferenceForces(*f, p, ref);
    const double force_err = (g - ref).cwiseAbs().maxCoeff() / ref.cwiseAbs().maxCoeff();
    std::printf("%s: E = %.6e J, reference %.6e J (rel %.1e), max force error %.1e relative\n",
                name, e, e_ref, std::abs(e - e_ref) / e_ref, force_err);
    EXPECT_NEAR(e, e_ref, 1e-10 * e_ref) << name;
    EXPECT_LT(force_err, 1e-10) << name;
  }
}

TEST(CorotationalTest, ForcesAreTheEnergyGradientWithFramesFixed) {
  // The analytic force holds the frames fixed; the finite difference of the
  // energy sees them move. The difference dE/dR . dR/dd is second order in
  // the local displacement, so it shrinks linearly with the strain: check
  // the relative error at two amplitudes (below 1 % of the strain) and that
  // it halves with them.
  auto f = Build("mixed", 2);
  const Points v = RandomPoints(f->nodes(), 7);
  const double h = 1e-6 * f->size() / v.cwiseAbs().maxCoeff();
  double previous = 0;
  for (double amplitude : {0.02, 0.01}) {
    const Points p = Deformed(f->rest, amplitude, Rotation(0.5, Eigen::Vector3d(-1, 2, 1)));
    Points g, scratch;
    f->model->Forces(p, g);
    const double an = Dot(g, v);
    const double ep = f->model->Forces(p + h * v, scratch);
    const double em = f->model->Forces(p - h * v, scratch);
    const double fd = (ep - em) / (2 * h);
    const double err = std::abs(fd - an) / std::abs(an);
    std::printf("strain ~%.2f: dE/dv analytic %.8e, FD %.8e, relative difference %.2e\n",
                amplitude, an, fd, err);
    EXPECT_LT(err, 0.01 * amplitude) << "amplitude " << amplitude;
    if (previous > 0) {
      EXPECT_LT(err, 0.7 * previous) << "the difference shrinks with the strain";
    }
    previous = err;
  }
}

TEST(CorotationalTest, UniformStrainGivesTheAnalyticEnergy) {
  const double lam = MaterialPoint{kYoung, kPoisson}.lame_lambda();
  const double mu = MaterialPoint{kYoung, kPoisson}.lame_mu();
  struct Case {
    const char* label;
    std::unique_ptr<Fixture> f;
    double volume;  // expected rest volume, 0: the layout's
  };
  std::vector<Case> cases;
  cases.push_back({"unit hexahedron, level 0",
                   BuildFrom(scene::ParseScene(R"pb(
                               mesh { block { nx: 1 ny: 1 nz: 1 } }
                               subdivision { levels: 0 }
                               materials { base { young_modulus: 1e5 poisson_ratio: 0.3 } }
                             )pb",
                                               "test"),
                             0),
                   1.0});
  cases.push_back({"block3, level 0", Build("block3", 0), 27.0});
  cases.push_back({"mixed, level 1", Build("mixed", 1), 0.0});
  const double e = 1e-3;
  for (Case& c : cases) {
    Fixture& f = *c.f;
    const double volume = c.volume > 0 ? c.volume : f.layout.rest_volume;
    EXPECT_NEAR(f.layout.rest_volume, volume, 1e-12 * volume) << c.label;
    int counts[3];
    for (int k = 0; k < 3; ++k) counts[k] = f.layout.blocks[k].size();
    // eps_xx = e: d = (I + e x x^T) x0 (symmetric, so the frame is I).
    Points stretched = f.rest;
    stretched.col(0) *= 1 + e;
    Points g;
    const double stretch = f.model->Forces(stretched, g);
    const double stretch_exact = 0.5 * (lam + 2 * mu) * e * e * volume;
    // Engineering shear gamma_xy = e: d_x += e/2 y, d_y += e/2 x (symmetric).
    Points sheared = f.rest;
    sheared.col(0) += 0.5 * e * f.rest.col(1);
    sheared.col(1) += 0.5 * e * f.rest.col(0);
    const double shear = f.model->Forces(sheared, g);
    const double shear_exact = 0.5 * mu * e * e * volume;
    std::printf("%s (%d cubic, %d linear, %d pyramid; V = %.6f): stretch E %.10e vs %.10e (rel "
                "%.1e), shear E %.10e vs %.10e (rel %.1e)\n",
                c.label, counts[0], counts[1], counts[2], volume, stretch, stretch_exact,
                std::abs(stretch / stretch_exact - 1), shear, shear_exact,
                std::abs(shear / shear_exact - 1));
    EXPECT_NEAR(stretch, stretch_exact, 1e-10 * stretch_exact) << c.label;
    EXPECT_NEAR(shear, shear_exact, 1e-10 * shear_exact) << c.label;
  }
}

TEST(CorotationalTest, ApplyLinearizedIsTheDerivativeOfTheForces) {
  auto f = Build("mixed", 2, 2, TwoMaterials());
  const Points v = RandomPoints(f->nodes(), 11);
  const Points w = RandomPoints(f->nodes(), 12);
  const double h = 1e-6 * f->size() / v.cwiseAbs().maxCoeff();
  // At rest and at a rigidly moved rest state the local displacement is zero,
  // so the frames' own derivative does not enter: the central difference of
  // the forces is R K R^T v up to O(h^2).
  struct State {
    const char* label;
    Points x;
  };
  const State states[] = {
      {"rest", f->rest},
      {"rotated rest",
       Rigid(f->rest, Rotation(0.9, Eigen::Vector3d(2, -1, 1)), Eigen::RowVector3d(5, 0, -2))}};
  for (const State& s : states) {
    Points gp, gm, g0, kv, kw;
    f->model->Forces(s.x + h * v, gp);
    f->model->Forces(s.x - h * v, gm);
    f->model->Forces(s.x, g0);  // the frames ApplyLinearized uses
    f->model->ApplyLinearized(v, kv);
    f->model->ApplyLinearized(w, kw);
    const Points fd = (gp - gm) / (2 * h);
    const double err = (kv - fd).norm() / fd.norm();
    const double asym = std::abs(Dot(w, kv) - Dot(v, kw)) / (kv.norm() * w.norm());
    std::printf("%s: |K v - FD| / |FD| = %.2e, |w.Kv - v.Kw| / (|Kv| |w|) = %.1e, v.Kv = %.3e\n",
                s.label, err, asym, Dot(v, kv));
    EXPECT_LT(err, 1e-7) << s.label;
    EXPECT_LT(asym, 1e-13) << s.label << ": symmetric";
    EXPECT_GT(Dot(v, kv), 0) << s.label << ": positive";
    // A rigid motion of the current state is in its null space.
    const Eigen::Vector3d omega(0.3, -0.2, 0.7);
    Points rigid(s.x.rows(), 3);
    for (int64_t i = 0; i < rigid.rows(); ++i) {
      rigid.row(i) = omega.cross(s.x.row(i).transpose()).transpose() + Eigen::RowVector3d(1, 2, 3);
    }
    f->model->ApplyLinearized(rigid, kw);
    EXPECT_LT(kw.norm(), 1e-10 * kv.norm() * rigid.norm() / v.norm()) << s.label;
  }
}

TEST(CorotationalTest, ResultsAreBitIdenticalForAnyPoolSize) {
  Points g1, k1;
  double e1 = 0;
  for (int threads : {1, 2, 3, 5}) {
    auto f = Build("mixed", 2, threads);
    const Points p = Deformed(f->rest, 0.02, Rotation(0.4, Eigen::Vector3d(1, 1, 0)));
    const Points v = RandomPoints(f->nodes(), 3);
    Points g, k;
    const double e = f->model->Forces(p, g);
    f->model->ApplyLinearized(v, k);
    if (threads == 1) {
      g1 = g;
      k1 = k;
      e1 = e;
      continue;
    }
    EXPECT_EQ(e, e1) << threads << " threads";
    EXPECT_TRUE(g == g1) << threads << " threads";
    EXPECT_TRUE(k == k1) << threads << " threads";
  }
}

TEST(CorotationalTest, AModelWithProductsWhenUsedMakesThemOnFirstUseWithTheSameBits) {
  auto f = Build("mixed", 2, 2);
  CorotationalModel lazy(f->layout, f->rest, *f->pool, nullptr, kEveryGroup,
                         CorotationalModel::Products::kWhenUsed);
  EXPECT_FALSE(lazy.has_products());
  EXPECT_TRUE(f->model->has_products());
  EXPECT_EQ(lazy.shared_matrix_bytes(), 0);
  EXPECT_EQ(lazy.quadrature_elements(), 0);
  // Its group choices are there before: what a cell corotation keys on.
  for (int kind = 0; kind < 3; ++kind) {
    for (size_t g = 0; g < f->layout.blocks[kind].groups.size(); ++g) {
      EXPECT_EQ(lazy.at_quadrature_points(kind, static_cast<int32_t>(g)),
                f->model->at_quadrature_points(kind, static_cast<int32_t>(g)));
    }
  }
  const Points p = Deformed(f->rest, 0.02, Rotation(0.4, Eigen::Vector3d(1, 1, 0)));
  const Points v = RandomPoints(f->nodes(), 3);
  // ApplyLinearized first (a const call), then Forces, as the eager model.
  Points k_lazy, k_now, g_lazy, g_now;
  lazy.ApplyLinearized(v, k_lazy);
  f->model->ApplyLinearized(v, k_now);
  EXPECT_TRUE(lazy.has_products());
  EXPECT_TRUE(k_lazy == k_now);
  EXPECT_EQ(lazy.Forces(p, g_lazy), f->model->Forces(p, g_now));
  EXPECT_TRUE(g_lazy == g_now);
  EXPECT_EQ(lazy.shared_matrix_bytes(), f->model->shared_matrix_bytes());
  EXPECT_EQ(lazy.quadrature_elements(), f->model->quadrature_elements());
}

TEST(CorotationalTest, ForcesAndApplyLinearizedDoNotAllocate) {
#if DYNSOLID_COUNT_MALLOCS
  auto f = Build("mixed", 2, 2);
  const Points p = Deformed(f->rest, 0.02, Rotation(0.4, Eigen::Vector3d(1, 1, 0)));
  const Points v = RandomPoints(f->nodes(), 5);
  const Points p2 = p + 1e-3 * v;
  Points g(f->nodes(), 3), k(f->nodes(), 3);
  g_mallocs = 0;
  g_count_mallocs = true;
  f->model->Forces(p, g);
  f->model->ApplyLinearized(v, k);
  f->model->Forces(p2, g);
  g_count_mallocs = false;
  EXPECT_EQ(g_mallocs.load(), 0);
  // The counter does count: a new matrix allocates.
  g_count_mallocs = true;
  const Points scaled = 2.0 * p;
  g_count_mallocs = false;
  EXPECT_GT(g_mallocs.load(), 0) << scaled.rows();
  std::printf("shared matrices %.3f MB, %lld bytes per element\n",
              f->model->shared_matrix_bytes() / 1e6,
              static_cast<long long>(f->model->per_element_bytes()));
#else
  GTEST_SKIP() << "allocation counting needs glibc without AddressSanitizer";
#endif
}

// Cubic elements applied at their quadrature points (cubic_quadrature.h,
// the isotropic law) give the dense K's products: on a curved mesh with a
// graded material, forces and the linearization in double to rounding, the
// single-precision linearization within its 1e-6.
TEST(CorotationalTest, QuadraturePointsGiveTheDenseProducts) {
  for (const auto& [name, levels] : {std::pair{"torus", 1}, std::pair{"mixed", 2}}) {
    auto f = Build(name, levels, 2, [](const Eigen::Vector3d& x, int32_t) {
      return MaterialPoint{kYoung * (1.5 + std::sin(2.0 * x.x() + x.z())),
                           0.3 + 0.1 * std::cos(3.0 * x.y()), 1000, 0};
    });
    CorotationalModel dense(f->layout, f->rest, *f->pool, nullptr, 0);
    CorotationalModel quad(f->layout, f->rest, *f->pool, nullptr, 1 << 30);
    const int64_t cubic = f->layout.blocks[0].size();
    ASSERT_GT(cubic, 0) << name;
    EXPECT_EQ(dense.quadrature_elements(), 0);
    EXPECT_EQ(quad.quadrature_elements(), cubic);
    EXPECT_EQ(quad.integrated_groups(),
              f->layout.blocks[1].groups.size() + f->layout.blocks[2].groups.size());
    // K of a pooled group, made from its quadrature points, is the dense
    // model's integrated one to rounding.
    for (int32_t g : {0, static_cast<int32_t>(f->layout.blocks[0].groups.size()) - 1}) {
      const Eigen::MatrixXd kq = quad.K(0, g), kd = dense.K(0, g);
      EXPECT_LE((kq - kd).cwiseAbs().maxCoeff(), 1e-13 * kd.cwiseAbs().maxCoeff()) << name;
      EXPECT_EQ(kq, kq.transpose()) << name;
    }
    const Points p = Deformed(f->rest, 0.02, Rotation(0.8, Eigen::Vector3d(1, 2, -1)));
    const Points v = RandomPoints(f->nodes(), 5);
    Points gd, gq, kd, kq, kf;
    const double ed = dense.Forces(p, gd), eq = quad.Forces(p, gq);
    dense.ApplyLinearized(v, kd);
    quad.ApplyLinearized(v, kq);
    quad.SetSinglePrecisionLinearized(true);
    quad.ApplyLinearized(v, kf);
    const double gs = gd.cwiseAbs().maxCoeff(), ks = kd.cwiseAbs().maxCoeff();
    std::printf("%s: %lld cubic elements at their quadrature points; force differs by %.1e, "
                "linearization by %.1e (double) and %.1e (float) of the largest entry\n",
                name, static_cast<long long>(cubic), (gq - gd).cwiseAbs().maxCoeff() / gs,
                (kq - kd).cwiseAbs().maxCoeff() / ks, (kf - kd).cwiseAbs().maxCoeff() / ks);
    EXPECT_NEAR(eq, ed, 1e-12 * ed) << name;
    EXPECT_LE((gq - gd).cwiseAbs().maxCoeff(), 1e-12 * gs) << name;
    EXPECT_LE((kq - kd).cwiseAbs().maxCoeff(), 1e-12 * ks) << name;
    EXPECT_GT((kf - kd).cwiseAbs().maxCoeff(), 0) << name << ": the float path ran";
    EXPECT_LE((kf - kd).cwiseAbs().maxCoeff(), 1e-6 * ks) << name;
  }
}

}  // namespace
}  // namespace dynsolid::models
