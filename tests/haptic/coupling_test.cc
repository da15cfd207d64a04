// The bridge's rendering logic (clients/haptic/coupling.h) and simulated
// devices, on a simulated clock: passivity bound, series coupling, model
// blend, force step bound, clamp, safety ramp. No wall time anywhere.
#include "clients/haptic/coupling.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <sched.h>

#include <thread>

#include "clients/haptic/device.h"
#include "clients/haptic/loop_clock.h"
#include "clients/haptic/metrics.h"

namespace dynsolid::haptic {
namespace {

using ::testing::HasSubstr;

constexpr double kT = 1e-3;

// A flat surface at height z with normal +z and stiffness k (N/m).
LocalModel Plane(double z, double k, int64_t step = 0) {
  LocalModel m;
  m.step = step;
  m.point = {0, 0, z};
  m.material_point = {0, 0, 3.0};
  m.normal = {0, 0, 1};
  m.stiffness = k;
  return m;
}

DeviceSample At(double z, double vz = 0) {
  DeviceSample d;
  d.position = {0, 0, z};
  d.velocity = {0, 0, vz};
  return d;
}

TEST(CouplingTest, StiffnessIsLimitedByThePassivityBound) {
  CouplingParams p;  // b = 20, B = 2, T = 1 ms, margin 0.8
  EXPECT_DOUBLE_EQ(p.PassiveStiffness(), 0.8 * 2 * (20 - 2) / 1e-3);
  Coupling c(p);
  double kc = 0;
  // A stiff model: K_c is the passivity bound (Colgate: b > K T / 2 + B).
  c.ModelForce(Plane(3.0, 1e6), 0, At(2.999), nullptr, &kc);
  EXPECT_DOUBLE_EQ(kc, p.PassiveStiffness());
  EXPECT_GT(p.device_damping, kc * p.period / 2 + p.virtual_damping);
  // A soft one: the coupling stays as stiff as allowed; the solid's own
  // softness comes in series.
  const Eigen::Vector3d soft = c.ModelForce(Plane(3.0, 1000), 0, At(2.999), nullptr, &kc);
  EXPECT_DOUBLE_EQ(kc, p.PassiveStiffness());
  EXPECT_NEAR(soft.z(), kc * 1000 / (kc + 1000) * 0.001, 1e-12);
  // A user cap.
  CouplingParams capped = p;
  capped.max_stiffness = 5000;
  Coupling c2(capped);
  c2.ModelForce(Plane(3.0, 1e6), 0, At(2.999), nullptr, &kc);
  EXPECT_DOUBLE_EQ(kc, 5000);
}

TEST(CouplingTest, ForceOpposesPenetrationAndGrowsWithDepth) {
  Coupling c(CouplingParams{});
  const LocalModel m = Plane(3.0, 2e4);
  double last = 0;
  for (double depth = 0.0002; depth < 0.003; depth += 0.0002) {
    const Eigen::Vector3d f = c.ModelForce(m, 0, At(3.0 - depth));
    EXPECT_GT(f.z(), last) << "depth " << depth;
    EXPECT_EQ(f.x(), 0);
    EXPECT_EQ(f.y(), 0);
    last = f.z();
  }
  // Outside: no force (and never a pull).
  EXPECT_EQ(c.ModelForce(m, 0, At(3.001)).norm(), 0);
  // Series springs: K_c (28800) with k (2e4).
  const double kc = CouplingParams{}.PassiveStiffness();
  const double k_ser = kc * 2e4 / (kc + 2e4);
  EXPECT_NEAR(c.ModelForce(m, 0, At(2.999)).z(), k_ser * 0.001, 1e-9);
}

// In quasi-static contact the solid carries F_s and the device sits F_s /
// K_c beyond the surface point: the model gives exactly F_s back.
TEST(CouplingTest, EquilibriumGivesBackTheCarriedForce) {
  Coupling c(CouplingParams{});
  LocalModel m = Plane(2.998, 1.5e4);
  m.applied_force = {0, 0, -25.0};  // on the solid: 25 N pushing in
  double kc = 0;
  c.ModelForce(m, 0, At(2.998), nullptr, &kc);
  const Eigen::Vector3d f = c.ModelForce(m, 0, At(2.998 - 25.0 / kc));
  EXPECT_NEAR(f.z(), 25.0, 1e-9);
}

TEST(CouplingTest, ViscousTermOpposesApproachVelocity) {
  CouplingParams p;
  Coupling c(p);
  const LocalModel m = Plane(3.0, 2e4);
  const double still = c.ModelForce(m, 0, At(2.999, 0)).z();
  const double moving_in = c.ModelForce(m, 0, At(2.999, -0.1)).z();
  EXPECT_NEAR(moving_in - still, p.virtual_damping * 0.1, 1e-9);
}

// Runs `ticks` ticks from time t (advanced), with `model` delivered at the
// first tick when given; returns the forces (z).
std::vector<double> Ticks(Coupling& c, double& t, int ticks, const DeviceSample& d,
                          const LocalModel* model = nullptr, double* largest_step = nullptr) {
  std::vector<double> out;
  for (int i = 0; i < ticks; ++i) {
    t += kT;
    if (model != nullptr && i == 0) c.OnModel(*model, t, d);
    const RenderedForce r = c.Compute(t, d);
    if (largest_step != nullptr) *largest_step = std::max(*largest_step, r.step);
    out.push_back(r.force.z());
  }
  return out;
}

TEST(CouplingTest, NewModelIsBlendedInOverBlendTime) {
  CouplingParams p;
  p.blend_time = 0.004;
  p.model_timeout = 1.0;  // not under test
  Coupling c(p);
  double t = 0;
  const DeviceSample d = At(2.998);
  LocalModel a = Plane(3.0, 2e4, 1);
  Ticks(c, t, 20, d, &a);  // settled on model a
  const double fa = c.ModelForce(a, 0, d).z();
  LocalModel b = Plane(2.9995, 2e4, 2);  // the surface yielded 0.5 mm
  const double fb = c.ModelForce(b, 0, d).z();
  ASSERT_LT(fb, fa - 1.0);
  std::vector<double> f = Ticks(c, t, 8, d, &b);
  // Linear from fa to fb over 4 ticks, then fb.
  for (int i = 0; i < 8; ++i) {
    const double w = std::max(0.0, 1.0 - i * kT / p.blend_time);
    EXPECT_NEAR(f[i], fb + w * (fa - fb), 1e-9) << "tick " << i;
  }
}

// Models arriving every tick do not freeze the force: the device's own
// motion still changes it at once.
TEST(CouplingTest, FrequentModelsStillFollowTheDevice) {
  CouplingParams p;
  p.model_timeout = 1.0;
  Coupling c(p);
  const LocalModel m = Plane(3.0, 2e4, 1);
  double t = 0;
  double last = 0;
  Ticks(c, t, 10, At(3.0), &m);  // blended in
  for (int i = 1; i <= 20; ++i) {
    t += kT;
    const DeviceSample d = At(3.0 - 1e-4 * i);
    c.OnModel(m, t, d);
    const double f = c.Compute(t, d).force.z();
    EXPECT_NEAR(f, c.ModelForce(m, 0, d).z(), 1e-9) << "tick " << i;
    EXPECT_GE(f, last);
    last = f;
  }
}

TEST(CouplingTest, NoForceStepExceedsTheBoundAndForceIsClamped) {
  CouplingParams p;
  p.max_force = 40;
  p.max_force_step = 5;
  p.blend_time = 1e-6;  // no blend: the step bound alone
  p.model_timeout = 1.0;
  Coupling c(p);
  double t = 0, largest = 0;
  // The device far inside a stiff model: 28.8 kN/m x 5 cm = way above 40 N.
  const LocalModel m = Plane(3.0, 1e6, 1);
  std::vector<double> f = Ticks(c, t, 20, At(2.95), &m, &largest);
  EXPECT_LE(largest, p.max_force_step + 1e-12);
  EXPECT_EQ(f[0], 0.0) << "the arrival tick continues the previous force";
  EXPECT_NEAR(f[1], 5.0, 1e-12);
  EXPECT_NEAR(f[7], 35.0, 1e-12);
  EXPECT_NEAR(f[8], 40.0, 1e-12) << "clamped at max_force after 8 bounded steps";
  EXPECT_NEAR(f.back(), 40.0, 1e-12);
}

// Default params (timeout 10 ms, ramp 10 ms), their coupling at time 0, and
// a device 1 mm into a stiff plane at z = 3 (the model the tests feed it).
struct PressedOnPlane {
  CouplingParams p;
  Coupling c{p};
  double t = 0;
  const DeviceSample d = At(2.999);
  const LocalModel m = Plane(3.0, 2e4, 1);
};

TEST(CouplingTest, SilentServerRampsToZeroWithinRampTimeAndStays) {
  PressedOnPlane s;
  auto& [p, c, t, d, m] = s;
  // Models every tick for 50 ms.
  for (int i = 0; i < 50; ++i) Ticks(c, t, 1, d, &m);
  const double f0 = c.Compute(t, d).force.z();
  ASSERT_GT(f0, 10.0);
  const double last_model = t;
  double largest = 0;
  std::vector<double> f = Ticks(c, t, 60, d, nullptr, &largest);
  // Held while the model is fresh, ramping from timeout, zero by timeout + ramp.
  for (size_t i = 0; i < f.size(); ++i) {
    const double ti = last_model + (i + 1) * kT;
    if (ti - last_model < p.model_timeout - 1e-9) {
      EXPECT_NEAR(f[i], f0, 1e-6) << "fresh at " << ti - last_model;
    }
    if (ti - last_model >= p.model_timeout + p.ramp_time - 1e-12) {
      EXPECT_EQ(f[i], 0.0) << "zero at " << ti - last_model;
    }
  }
  EXPECT_LE(largest, f0 * kT / p.ramp_time * (1 + 1e-6)) << "a linear ramp";
  EXPECT_GT(largest, 0.99 * f0 * kT / p.ramp_time);
  EXPECT_TRUE(c.safe_state());
  // A model again: blended in from zero within the step bound.
  largest = 0;
  f = Ticks(c, t, 10, d, &m, &largest);
  EXPECT_LE(largest, p.max_force_step + 1e-12);
  EXPECT_FALSE(c.safe_state());
  EXPECT_NEAR(f.back(), c.ModelForce(m, 0, d).z(), 1e-6);
}

TEST(CouplingTest, BrokenLinkRampsToZeroWithinRampTime) {
  PressedOnPlane s;
  auto& [p, c, t, d, m] = s;
  for (int i = 0; i < 20; ++i) Ticks(c, t, 1, d, &m);
  const double f0 = c.Compute(t, d).force.z();
  c.SetLinkUp(false, t);
  std::vector<double> f = Ticks(c, t, 15, d);
  // Zero at most ramp_time after the break.
  for (size_t i = 0; i < f.size(); ++i) {
    if ((i + 1) * kT >= p.ramp_time - 1e-12) {
      EXPECT_EQ(f[i], 0.0) << "tick " << i;
    }
    if (i > 0) {
      EXPECT_LE(f[i], f[i - 1]);
    }
  }
  EXPECT_NEAR(f[0], 0.9 * f0, 1e-9) << "the first tick after the break lowers it";
}

TEST(CouplingTest, ParamsAreValidated) {
  CouplingParams p;
  EXPECT_TRUE(p.Validate().ok());
  CouplingParams slow = p;
  slow.max_force_step = 1.0;  // 40 N cannot reach zero in 10 ticks
  EXPECT_THAT(std::string(slow.Validate().message()), HasSubstr("max_force_step"));
  CouplingParams damp = p;
  damp.virtual_damping = 15;  // > b / 2
  EXPECT_THAT(std::string(damp.Validate().message()), HasSubstr("virtual_damping"));
  CouplingParams zero = p;
  zero.period = 0;
  EXPECT_FALSE(zero.Validate().ok());
}

// The loop closed on a simulated solid (a surface point of mass M, static
// stiffness ks and damping bs under the reaction force), models refreshed
// every 3 ms with 2 ms of delay, a virtual hand pushing in: the force
// settles (no growing oscillation) at the series answer, and the rendered
// stiffness never exceeds the passivity bound.
TEST(CouplingTest, ClosedLoopOnASimulatedSolidSettlesAtTheSeriesForce) {
  CouplingParams p;
  Coupling c(p);
  auto target = Trajectory::Parse("0 0 0 3.02\n0.2 0 0 3.02\n1.2 0 0 2.99\n4 0 0 2.99\n", "t");
  ASSERT_TRUE(target.ok()) << target.status();
  DeviceParams dp;
  dp.hand_stiffness = 500;
  VirtualHand hand(*target, dp);
  const double ks = 1.2e4, mass = 50.0, bs = 800.0;
  double zs = 3.0, vs = 0;  // the surface point
  double t = 0;
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  std::vector<std::pair<double, LocalModel>> in_flight;  // delivery time, model
  double applied = 0;                                    // force on the solid (pushing in)
  double next_model = 0;
  std::vector<double> forces;
  for (int i = 0; i < 4000; ++i) {
    t += kT;
    // The solid: M a = -ks (z - 3) - bs v - applied, stepped at 1 ms.
    const double a = (-ks * (zs - 3.0) - bs * vs - applied) / mass;
    vs += kT * a;
    zs += kT * vs;
    if (t >= next_model) {
      LocalModel m = Plane(zs, 9e5, i);
      m.velocity = {0, 0, vs};
      m.applied_force = {0, 0, -applied};
      in_flight.emplace_back(t + 0.002, m);
      next_model = t + 0.003;
    }
    const DeviceState ds = hand.Read(t);
    const DeviceSample d{ds.position, ds.velocity};
    while (!in_flight.empty() && in_flight.front().first <= t) {
      c.OnModel(in_flight.front().second, t, d);
      in_flight.erase(in_flight.begin());
    }
    const RenderedForce r = c.Compute(t, d);
    EXPECT_LE(r.coupling_stiffness, p.PassiveStiffness() + 1e-9);
    f = r.force;
    hand.Write(f, t);
    applied = f.z();  // the reaction on the solid (its next step)
    forces.push_back(f.z());
  }
  // Steady state: the hand's spring holds the force; the solid carries it.
  const double settled = forces.back();
  EXPECT_GT(settled, 1.0);
  EXPECT_NEAR(settled, ks * (3.0 - zs), 0.02 * settled) << "the solid carries the force";
  double lo = 1e9, hi = -1e9;
  for (size_t i = forces.size() - 500; i < forces.size(); ++i) {
    lo = std::min(lo, forces[i]);
    hi = std::max(hi, forces[i]);
  }
  EXPECT_LT(hi - lo, 0.01 * settled) << "settled, no oscillation";
}

TEST(DeviceTest, TrajectoryParsesInterpolatesAndNamesBadLines) {
  auto t = Trajectory::Parse("# comment\n0 0 0 0\n1 1 2 3 # key\n2 1 2 3 1 0 0 0 5\n", "x.txt");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_NEAR(t->At(0.5).x.y(), 1.0, 1e-12);
  EXPECT_NEAR(t->VelocityAt(0.5).z(), 3.0, 1e-12);
  EXPECT_EQ(t->At(5).x, Eigen::Vector3d(1, 2, 3));
  EXPECT_DOUBLE_EQ(t->duration(), 2.0);
  EXPECT_THAT(std::string(Trajectory::Parse("0 0 0\n", "a.txt").status().message()),
              HasSubstr("a.txt:1:"));
  EXPECT_THAT(std::string(Trajectory::Parse("0 0 0 0\n0 1 1 1\n", "b.txt").status().message()),
              HasSubstr("b.txt:2: t = 0 must be after"));
  EXPECT_THAT(std::string(Trajectory::Parse("0 0 nan 0\n", "c.txt").status().message()),
              HasSubstr("not a finite number"));
}

TEST(DeviceTest, VirtualHandSettlesOnItsTargetAndYieldsToForce) {
  auto t = Trajectory::Parse("0 0 0 1\n0.1 0 0 1\n", "hand");
  ASSERT_TRUE(t.ok());
  DeviceParams p;
  p.hand_mass = 0.5;
  p.hand_stiffness = 1000;
  p.damping = 20;
  VirtualHand hand(*t, p);
  hand.Write(Eigen::Vector3d(0, 0, 5.0), 0);  // 5 N up
  DeviceState s;
  for (int i = 1; i <= 3000; ++i) s = hand.Read(i * 1e-3);
  EXPECT_NEAR(s.position.z(), 1.0 + 5.0 / 1000, 1e-6) << "F / k from the target";
  EXPECT_NEAR(s.velocity.norm(), 0, 1e-6);
}

TEST(MetricsTest, PercentilesAndSummary) {
  EXPECT_EQ(Percentile({}, 0.5), 0);
  EXPECT_EQ(Percentile({3, 1, 2}, 0.5), 2);
  EXPECT_EQ(Percentile({1, 2, 3, 4}, 0.99), 4);
  LoopMetrics m(1e-3, 16);
  m.Tick(0.001, 0.001, 1e-6, 0.5, -1);
  m.Tick(0.0021, 0.002, 2e-6, 1.5, 0.002);
  m.Tick(0.0030, 0.003, 1e-6, 0.1, 0.001);
  const LoopSummary s = m.Summarize(0.003);
  EXPECT_EQ(s.ticks, 3);
  EXPECT_NEAR(s.period_max_us, 1100, 1e-6);
  EXPECT_NEAR(s.period_error_max_us, 100, 1e-6);
  EXPECT_EQ(s.deadline_misses, 0);  // 100 us late < 250 us
  EXPECT_DOUBLE_EQ(s.largest_force_step_n, 1.5);
  EXPECT_THAT(s.Json(), HasSubstr("\"period_p999_us\""));
}

// --cpu: the loop's thread runs on the CPU it asked for, the threads
// started after KeepOffCpu never do, and a CPU that does not exist is
// refused by name. (On a one-CPU machine only the refusal is checked.)
TEST(LoopClockTest, PinsTheLoopAndKeepsOtherThreadsOffItsCpu) {
  EXPECT_THAT(TryPin(1 << 20), HasSubstr("not pinned (CPU 1048576 out of range"));
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  ASSERT_EQ(sched_getaffinity(0, sizeof(allowed), &allowed), 0);
  if (CPU_COUNT(&allowed) < 2) GTEST_SKIP() << "one CPU: nothing to keep apart";
  int loop_cpu = -1;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (CPU_ISSET(c, &allowed)) loop_cpu = c;
  }
  std::thread([&] {
    EXPECT_THAT(KeepOffCpu(loop_cpu), HasSubstr("other threads on CPUs"));
    cpu_set_t inherited;
    bool other_ran_there = true;
    std::thread([&] {
      CPU_ZERO(&inherited);
      (void)sched_getaffinity(0, sizeof(inherited), &inherited);
      other_ran_there = CPU_ISSET(loop_cpu, &inherited);
    }).join();
    EXPECT_FALSE(other_ran_there) << "a thread started later may still run on CPU " << loop_cpu;
    EXPECT_EQ(TryPin(loop_cpu), "pinned to CPU " + std::to_string(loop_cpu));
    EXPECT_EQ(sched_getcpu(), loop_cpu);
  }).join();
}

}  // namespace
}  // namespace dynsolid::haptic
