// dynsolid-haptic-bridge: runs beside a haptic device, renders forces at
// 1 kHz from the contact models a dynsolid-server session sends, and sends
// the probe's poses (with the force it rendered) back (docs/haptic.md).
//
//   dynsolid-haptic-bridge [--server HOST:PORT] (--id ID --token TOKEN | --scene NAME [--levels L])
//       --device virtual_hand|trajectory --script FILE [--seconds S]
//       [--json METRICS.json] [--trace TRACE.csv] [coupling and device flags]
//
// Prints the loop metrics at exit (and writes them as JSON with --json).
// Exit codes: 0 done; 1 the server refused the probe (wrong token, no such
// session); 2 bad flags or script.
#include <grpcpp/grpcpp.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "clients/haptic/bridge.h"
#include "clients/haptic/coupling.h"
#include "clients/haptic/device.h"
#include "clients/haptic/loop_clock.h"
#include "clients/haptic/probe_link.h"
#include "clients/lib/channel.h"
#include "cmdline/cmdline.h"
#include "dynsolid/service.grpc.pb.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "dynsolid-server address, HOST:PORT");
ABSL_FLAG(std::string, id, "", "the session to probe (with --token)");
ABSL_FLAG(std::string, token, "", "the session's token");
ABSL_FLAG(std::string, scene, "", "create a session of this built-in scene instead of --id");
ABSL_FLAG(int, levels, -1, "with --scene: subdivision levels (-1: the scene's)");
ABSL_FLAG(std::string, device, "virtual_hand",
          "virtual_hand (a mass on a spring driven to the script's target) or trajectory (the "
          "script's poses, open loop)");
ABSL_FLAG(std::string, script, "",
          "the device's script: lines \"t x y z [qw qx qy qz [buttons]]\"");
ABSL_FLAG(double, seconds, 0, "run this long; 0: until the script ends");
ABSL_FLAG(std::string, json, "", "write the loop metrics here as JSON");
ABSL_FLAG(std::string, trace, "", "write a per-tick CSV trace here (force-depth curves)");
ABSL_FLAG(double, period_ms, 1.0, "loop period T, ms");
ABSL_FLAG(double, max_force, 40.0, "the device's largest force, N");
ABSL_FLAG(double, device_damping, 20.0, "the device's physical damping b, N s/m");
ABSL_FLAG(double, virtual_damping, 2.0, "rendered damping B, N s/m (at most b / 2)");
ABSL_FLAG(double, max_stiffness, 1e9, "cap on the coupling stiffness K_c, N/m");
ABSL_FLAG(double, passivity_margin, 0.8, "K_c <= margin * 2 (b - B) / T");
ABSL_FLAG(double, max_force_step, 10.0, "largest force change per tick, N");
ABSL_FLAG(double, blend_ms, 3.0, "a new contact model is blended in over this, ms");
ABSL_FLAG(double, model_timeout_ms, 10.0, "no model for this long: ramp the force to zero, ms");
ABSL_FLAG(double, ramp_ms, 10.0, "the safety ramp to zero takes this long, ms");
ABSL_FLAG(double, hand_mass, 0.5, "virtual_hand: mass, kg");
ABSL_FLAG(double, hand_stiffness, 2000.0, "virtual_hand: spring to the target, N/m");
ABSL_FLAG(double, near, 0,
          "contact models while the probe is within this of the surface, m "
          "(0: the server's default, 10 % of the solid's size)");
ABSL_FLAG(double, horizon, 0, "the contact model's horizon tau, s (0: the server's 0.03)");
ABSL_FLAG(int, rt_priority, 80, "SCHED_FIFO priority to ask for (0: do not ask)");
ABSL_FLAG(int, cpu, -1,
          "pin the loop to this CPU and keep the bridge's other threads off it (-1: do not pin)");
ABSL_FLAG(double, spin_us, 100, "sleep to this long before each deadline, then spin, us");
ABSL_FLAG(bool, verbose, false, "log reconnects and refusals to stderr");

namespace {

namespace dh = dynsolid::haptic;
namespace dc = dynsolid::client;

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop.store(true); }

int Usage(const std::string& message) {
  std::cerr << "dynsolid-haptic-bridge: " << message << "\n";
  return 2;
}

// The server's view at exit: the session's step, probes and contact phase.
void PrintServerStats(dynsolid::Sessions::Stub& stub, const dynsolid::SessionRef& ref) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  dynsolid::SessionStats st;
  if (!stub.GetStats(&context, ref, &st).ok()) return;
  std::string contact = "absent";
  for (const auto& p : st.phases()) {
    if (p.name() == "contact") contact = absl::StrCat(p.median_ms(), " ms median");
  }
  std::printf(
      "server: session %s at step %ld, %.1f steps/s, step %.3f ms median; probes now %d "
      "(%ld in all); contact phase %s\n",
      ref.id().c_str(), static_cast<long>(st.step()), st.steps_per_second(), st.step_ms_median(),
      st.probes(), static_cast<long>(st.probes_total()), contact.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  dynsolid::cmdline::ParseCommandLine(
      argc, argv,
      "dynsolid-haptic-bridge [--server HOST:PORT] (--id ID --token TOKEN | --scene NAME) "
      "--device virtual_hand|trajectory --script FILE [--seconds S] [--json F] [--trace F]",
      __FILE__);
  dynsolid::cmdline::CheckHostPortOrExit("dynsolid-haptic-bridge", "--server",
                                         absl::GetFlag(FLAGS_server), /*allow_port_zero=*/false,
                                         /*allow_uri=*/true);
  signal(SIGINT, OnSignal);
  signal(SIGTERM, OnSignal);

  dh::CouplingParams cp;
  cp.period = absl::GetFlag(FLAGS_period_ms) * 1e-3;
  cp.max_force = absl::GetFlag(FLAGS_max_force);
  cp.device_damping = absl::GetFlag(FLAGS_device_damping);
  cp.virtual_damping = absl::GetFlag(FLAGS_virtual_damping);
  cp.max_stiffness = absl::GetFlag(FLAGS_max_stiffness);
  cp.passivity_margin = absl::GetFlag(FLAGS_passivity_margin);
  cp.max_force_step = absl::GetFlag(FLAGS_max_force_step);
  cp.blend_time = absl::GetFlag(FLAGS_blend_ms) * 1e-3;
  cp.model_timeout = absl::GetFlag(FLAGS_model_timeout_ms) * 1e-3;
  cp.ramp_time = absl::GetFlag(FLAGS_ramp_ms) * 1e-3;
  if (absl::Status s = cp.Validate(); !s.ok()) return Usage(std::string(s.message()));

  dh::DeviceParams dp;
  dp.damping = cp.device_damping;
  dp.max_force = cp.max_force;
  dp.hand_mass = absl::GetFlag(FLAGS_hand_mass);
  dp.hand_stiffness = absl::GetFlag(FLAGS_hand_stiffness);
  if (absl::GetFlag(FLAGS_script).empty()) return Usage("--script FILE is required");
  absl::StatusOr<std::unique_ptr<dh::Device>> device =
      dh::MakeDevice(absl::GetFlag(FLAGS_device), absl::GetFlag(FLAGS_script), dp);
  if (!device.ok()) return Usage(std::string(device.status().message()));

  // Before any other thread starts: they inherit this thread's CPUs, and
  // the loop (this thread again, in Bridge::Run) pins itself to --cpu.
  if (absl::GetFlag(FLAGS_cpu) >= 0) {
    std::fprintf(stderr, "bridge: %s\n", dh::KeepOffCpu(absl::GetFlag(FLAGS_cpu)).c_str());
  }
  dc::ChannelOptions co;
  co.address = absl::GetFlag(FLAGS_server);
  const dc::ChannelFactory channels = dc::ChannelFactoryFor(co);
  auto stub = dynsolid::Sessions::NewStub(channels());
  dynsolid::SessionRef ref;
  if (!absl::GetFlag(FLAGS_scene).empty()) {
    dynsolid::CreateSessionRequest req;
    req.set_builtin_scene(absl::GetFlag(FLAGS_scene));
    if (absl::GetFlag(FLAGS_levels) >= 0) req.set_levels_override(absl::GetFlag(FLAGS_levels));
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    dynsolid::Session session;
    const grpc::Status st = stub->CreateSession(&context, req, &session);
    if (!st.ok()) {
      std::cerr << "CreateSession: " << st.error_message() << "\n";
      return 1;
    }
    ref.set_id(session.id());
    ref.set_token(session.token());
    channels.Follow(session);  // the replica that owns it, when there are several
    std::printf("session %s token %s (scene %s)\n", session.id().c_str(), session.token().c_str(),
                session.scene_name().c_str());
  } else {
    if (absl::GetFlag(FLAGS_id).empty() || absl::GetFlag(FLAGS_token).empty()) {
      return Usage("give --id and --token, or --scene");
    }
    ref.set_id(absl::GetFlag(FLAGS_id));
    ref.set_token(absl::GetFlag(FLAGS_token));
  }

  dh::ProbeLinkOptions lo;
  lo.channels = channels;
  lo.session = ref;
  lo.options.set_near_distance(absl::GetFlag(FLAGS_near));
  lo.options.set_horizon(absl::GetFlag(FLAGS_horizon));
  if (absl::GetFlag(FLAGS_verbose)) {
    lo.log = [](const std::string& m) { std::fprintf(stderr, "bridge: %s\n", m.c_str()); };
  }
  dh::ProbeLink link(lo);
  link.Start();

  dh::BridgeOptions bo;
  bo.coupling = cp;
  bo.seconds = absl::GetFlag(FLAGS_seconds);
  bo.rt_priority = absl::GetFlag(FLAGS_rt_priority);
  bo.cpu = absl::GetFlag(FLAGS_cpu);
  bo.trace = !absl::GetFlag(FLAGS_trace).empty();
  bo.spin_margin = absl::GetFlag(FLAGS_spin_us) * 1e-6;
  dh::Bridge bridge(**device, &link, bo);
  std::fprintf(stderr,
               "bridge: %s device, K_c <= %.0f N/m (passivity: 2 (b - B) / T x %.2f), "
               "max force %.1f N, step bound %.2f N\n",
               (*device)->name().c_str(), cp.PassiveStiffness(), cp.passivity_margin, cp.max_force,
               cp.max_force_step);
  const dh::LoopSummary summary = bridge.Run(g_stop);
  link.Stop();
  std::cout << summary.Text();
  PrintServerStats(*stub, ref);
  if (!absl::GetFlag(FLAGS_json).empty()) {
    std::ofstream(absl::GetFlag(FLAGS_json)) << summary.Json();
  }
  if (!absl::GetFlag(FLAGS_trace).empty()) {
    std::ofstream(absl::GetFlag(FLAGS_trace)) << bridge.TraceCsv();
  }
  const absl::Status final_status = link.counters().final_status;
  if (!final_status.ok()) {
    std::cerr << "dynsolid-haptic-bridge: " << final_status.message() << "\n";
    return 1;
  }
  return 0;
}
