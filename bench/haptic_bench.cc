// haptic_bench: the bridge's 1 kHz loop against a real dynsolid-server on
// the same machine (docs/haptic.md, "Benchmark").
//
// Starts dynsolid-server, opens a session of block3 (its own levels unless
// --levels), attaches one watcher (a decoding client on its own
// connection, at 60 Hz), and runs the bridge's loop in this process with a
// virtual hand pressing into the top face and letting go in cycles for
// --seconds. Prints the loop's figures (period and its error p50 / p99 /
// p99.9 / max, deadline misses, model age, refresh rate against the
// server's step rate, largest force step, force computation per tick) and
// the targets next to them. Figures only: nothing here is a test.
//
// By default the loop runs alone on the last CPU (everything else, the
// server included, on the others) and spins 900 us of each period; the
// watcher is a process of its own, as a viewer is.
//
//   haptic_bench [--seconds 20] [--levels L] [--loop_cpu C] [--spin_us U]
//                [--watcher_process] [--server_flags "..."] [--json F]
#include <fcntl.h>
#include <sched.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "clients/haptic/bridge.h"
#include "clients/haptic/device.h"
#include "clients/haptic/loop_clock.h"
#include "clients/haptic/probe_link.h"
#include "clients/lib/channel.h"
#include "clients/lib/watcher.h"
#include "dynsolid/service.grpc.pb.h"

ABSL_FLAG(std::string, server_binary, "",
          "dynsolid-server to start (default: ../server/dynsolid-server next to this binary)");
ABSL_FLAG(std::string, scene, "block3", "built-in scene");
ABSL_FLAG(int, levels, -1, "subdivision levels (-1: the scene's)");
ABSL_FLAG(double, seconds, 20, "how long the loop runs");
ABSL_FLAG(std::string, server_flags, "--stream_idle=false --stream_nice=0",
          "flags for the server, separated by spaces (the default runs its streaming threads at "
          "normal priority, as docs/haptic.md recommends for a haptic server)");
ABSL_FLAG(std::string, server_log, "/dev/null", "where the server's log goes");
ABSL_FLAG(int, watchers, 1, "watchers of the session while the loop runs");
ABSL_FLAG(bool, watcher_process, true,
          "run the watchers in a process of their own, as a viewer is (false: in this process, "
          "beside the loop)");
// Internal: the child that --watcher_process starts runs only watchers.
ABSL_FLAG(std::string, watch_only, "", "internal: ADDRESS,ID,TOKEN,SECONDS: only watch");
ABSL_FLAG(std::string, json, "", "write the loop's metrics here");
ABSL_FLAG(int, rt_priority, 80, "SCHED_FIFO priority the loop asks for (0: none)");
ABSL_FLAG(int, loop_cpu, -2,
          "pin the loop to this CPU and run everything else (the server, the watchers, gRPC's "
          "threads) on the others (-1: pin nothing; -2: the last CPU this process may use)");
ABSL_FLAG(double, spin_us, 900,
          "the loop spins this long before each deadline, us (900: it sleeps 100 us a period; "
          "on a VM an idle vCPU wakes late, docs/haptic.md \"Benchmark\")");

namespace {

namespace dh = dynsolid::haptic;
namespace dc = dynsolid::client;

// This binary's path.
std::filesystem::path SelfPath(const char* argv0) {
  std::error_code ec;
  std::filesystem::path self = std::filesystem::canonical("/proc/self/exe", ec);
  return ec ? std::filesystem::path(argv0) : self;
}

std::string DefaultServerBinary(const char* argv0) {
  return (SelfPath(argv0).parent_path().parent_path() / "server" / "dynsolid-server").string();
}

// `n` decoding watchers of the session at 60 Hz, each on its own channel.
std::vector<std::unique_ptr<dc::Watcher>> StartWatchers(const dc::ChannelFactory& channels,
                                                        const dynsolid::SessionRef& ref, int n) {
  std::vector<std::unique_ptr<dc::Watcher>> watchers;
  for (int i = 0; i < n; ++i) {
    dc::WatcherOptions wo;
    wo.rate_hz = 60;
    watchers.push_back(std::make_unique<dc::Watcher>(channels, ref, wo));
  }
  return watchers;
}

// A child process running `args` (args[0] the binary), its stdout a pipe
// to this one and, with `with_stdin`, its stdin a pipe from this one (it
// sees end of file when CloseStdin is called); stderr to `log` if given.
// It gets SIGTERM when this process dies, and at destruction.
class Child {
 public:
  Child(std::vector<std::string> args, bool with_stdin, const std::string& log = "") {
    int out[2], in[2] = {-1, -1};
    if (::pipe(out) != 0 || (with_stdin && ::pipe(in) != 0)) return;
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != parent) ::_exit(127);
      ::dup2(out[1], 1);
      ::close(out[0]);
      if (with_stdin) {
        ::dup2(in[0], 0);
        ::close(in[1]);
      }
      if (!log.empty()) {
        const int err = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600);
        if (err >= 0) ::dup2(err, 2);
      }
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(out[1]);
    out_ = out[0];
    if (with_stdin) {
      ::close(in[0]);
      in_ = in[1];
    }
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child() {
    if (in_ >= 0) ::close(in_);
    if (out_ >= 0) ::close(out_);
    Wait(SIGTERM);
  }
  // A line of its stdout, without the newline ("" at end of file).
  std::string ReadLine() {
    std::string line;
    char c;
    while (out_ >= 0 && ::read(out_, &c, 1) == 1 && c != '\n') line.push_back(c);
    return line;
  }
  void CloseStdin() {
    if (in_ >= 0) ::close(in_);
    in_ = -1;
  }
  // Sends `signal` (0: none, it ends by itself) and reaps it.
  void Wait(int signal) {
    if (pid_ <= 0) return;
    if (signal != 0) ::kill(pid_, signal);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }

 private:
  pid_t pid_ = -1;
  int out_ = -1, in_ = -1;
};

// dynsolid-server on a free loopback port.
class ServerProcess {
 public:
  ServerProcess(const std::string& binary, const std::string& log,
                const std::vector<std::string>& extra)
      : child_(Args(binary, extra), /*with_stdin=*/false, log) {
    const std::string line = child_.ReadLine();
    const std::string prefix = "listening on ";
    if (line.rfind(prefix, 0) == 0) address_ = line.substr(prefix.size());
  }
  const std::string& address() const { return address_; }

 private:
  static std::vector<std::string> Args(const std::string& binary,
                                       const std::vector<std::string>& extra) {
    std::vector<std::string> args = {binary, "--listen=127.0.0.1:0"};
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  }
  Child child_;
  std::string address_;
};

// The watchers in a child process: this binary again with --watch_only.
// It prints its frame count on its stdout when the parent closes its stdin.
class WatcherProcess {
 public:
  WatcherProcess(const std::string& self, const std::string& spec, int watchers)
      : child_({self, "--watch_only=" + spec, "--watchers=" + std::to_string(watchers)},
               /*with_stdin=*/true) {}
  // Stops the watchers and returns the frames they decoded.
  long Finish() {
    child_.CloseStdin();
    const long frames = std::atol(child_.ReadLine().c_str());
    child_.Wait(0);
    return frames;
  }

 private:
  Child child_;
};

// --watch_only=ADDRESS,ID,TOKEN: watch at 60 Hz until stdin closes.
int WatchOnly(const std::string& spec, int n) {
  std::vector<std::string> f = absl::StrSplit(spec, ',');
  if (f.size() != 3) {
    std::fprintf(stderr, "haptic_bench: --watch_only wants ADDRESS,ID,TOKEN, got %s\n",
                 spec.c_str());
    return 2;
  }
  dc::ChannelOptions co;
  co.address = f[0];
  const dc::ChannelFactory channels = dc::ChannelFactoryFor(co);
  dynsolid::SessionRef ref;
  ref.set_id(f[1]);
  ref.set_token(f[2]);
  std::vector<std::unique_ptr<dc::Watcher>> watchers = StartWatchers(channels, ref, n);
  char c;
  while (::read(0, &c, 1) > 0) {
  }
  long frames = 0;
  for (auto& w : watchers) frames += w->Counts().frames;
  for (auto& w : watchers) (void)w->Stop();
  std::printf("%ld\n", frames);
  std::fflush(stdout);
  return 0;
}

// Press 8 mm below the top face's centre... and let go, every 4 s.
std::string HandScript(double seconds) {
  std::string s;
  for (double t = 0; t < seconds + 4; t += 4) {
    absl::StrAppendFormat(&s,
                          "%g 1.5 1.5 3.03\n%g 1.5 1.5 3.03\n%g 1.5 1.5 2.95\n"
                          "%g 1.5 1.5 2.95\n",
                          t, t + 0.5, t + 2.0, t + 3.5);
  }
  return s;
}

dynsolid::SessionStats Stats(dynsolid::Sessions::Stub& stub, const dynsolid::SessionRef& ref) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  dynsolid::SessionStats st;
  (void)stub.GetStats(&context, ref, &st);
  return st;
}

// Milliseconds of CPU steal so far, all CPUs (/proc/stat "cpu" line, 8th
// value, in USER_HZ ticks of 10 ms).
double SumSteal() {
  std::ifstream in("/proc/stat");
  std::string cpu;
  double v[8] = {0};
  in >> cpu;
  for (double& x : v) in >> x;
  return v[7] * 10.0;
}

}  // namespace

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  if (!absl::GetFlag(FLAGS_watch_only).empty()) {
    return WatchOnly(absl::GetFlag(FLAGS_watch_only), absl::GetFlag(FLAGS_watchers));
  }
  // Before the server and any thread start: they inherit the CPUs left.
  int loop_cpu = absl::GetFlag(FLAGS_loop_cpu);
  if (loop_cpu == -2) {
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    loop_cpu = -1;
    if (sched_getaffinity(0, sizeof(allowed), &allowed) == 0) {
      for (int c = 0; c < CPU_SETSIZE; ++c) {
        if (CPU_ISSET(c, &allowed)) loop_cpu = c;
      }
    }
  }
  const std::string others = loop_cpu >= 0 ? dh::KeepOffCpu(loop_cpu) : "nothing pinned";
  std::string binary = absl::GetFlag(FLAGS_server_binary);
  if (binary.empty()) binary = DefaultServerBinary(argv[0]);
  std::vector<std::string> extra =
      absl::StrSplit(absl::GetFlag(FLAGS_server_flags), ' ', absl::SkipEmpty());
  ServerProcess server(binary, absl::GetFlag(FLAGS_server_log), extra);
  if (server.address().empty()) {
    std::fprintf(stderr, "haptic_bench: %s did not start\n", binary.c_str());
    return 1;
  }
  dc::ChannelOptions co;
  co.address = server.address();
  const dc::ChannelFactory channels = dc::ChannelFactoryFor(co);
  auto stub = dynsolid::Sessions::NewStub(channels());
  dynsolid::CreateSessionRequest req;
  req.set_builtin_scene(absl::GetFlag(FLAGS_scene));
  if (absl::GetFlag(FLAGS_levels) >= 0) req.set_levels_override(absl::GetFlag(FLAGS_levels));
  dynsolid::Session session;
  {
    grpc::ClientContext context;
    const grpc::Status st = stub->CreateSession(&context, req, &session);
    if (!st.ok()) {
      std::fprintf(stderr, "CreateSession: %s\n", st.error_message().c_str());
      return 1;
    }
  }
  dynsolid::SessionRef ref;
  ref.set_id(session.id());
  ref.set_token(session.token());
  std::printf(
      "server %s (%s), session of %s at %d levels: %d cells, %d control points; h = "
      "%g s\n",
      server.address().c_str(), absl::GetFlag(FLAGS_server_flags).c_str(),
      session.scene_name().c_str(), session.stats().levels(), session.stats().cells(),
      session.stats().control_vertices(), session.time_step());

  // A viewer is a process of its own (a browser, the CLI); by default so
  // is the benchmark's watcher. In this process its decoding allocates and
  // maps memory beside the loop (measured: 8-19 deadline misses in 20 s
  // against 1 with no watcher; docs/haptic.md).
  std::vector<std::unique_ptr<dc::Watcher>> watchers;
  std::unique_ptr<WatcherProcess> watcher_process;
  const int nwatch = absl::GetFlag(FLAGS_watchers);
  if (nwatch > 0 && absl::GetFlag(FLAGS_watcher_process)) {
    watcher_process = std::make_unique<WatcherProcess>(
        SelfPath(argv[0]).string(),
        absl::StrCat(server.address(), ",", session.id(), ",", session.token()), nwatch);
  } else {
    watchers = StartWatchers(channels, ref, nwatch);
  }

  const double seconds = absl::GetFlag(FLAGS_seconds);
  absl::StatusOr<dh::Trajectory> target = dh::Trajectory::Parse(HandScript(seconds), "bench");
  if (!target.ok()) return 1;
  dh::DeviceParams dp;
  dp.hand_stiffness = 500;
  dh::VirtualHand hand(*target, dp);
  dh::ProbeLinkOptions lo;
  lo.channels = channels;
  lo.session = ref;
  dh::ProbeLink link(lo);
  link.Start();
  // Let the session build its contact stiffness before the clock starts
  // (the first model; its build is a one-time hold of the loop).
  for (int i = 0; i < 400 && link.counters().models == 0; ++i) {  // seqs below 1000
    dynsolid::ProbePose pose;
    pose.set_seq(i + 1);
    pose.mutable_position()->set_x(1.5);
    pose.mutable_position()->set_y(1.5);
    pose.mutable_position()->set_z(3.03);
    link.PostPose(pose);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const dynsolid::SessionStats before = Stats(*stub, ref);
  const double steal0 = SumSteal();
  dh::BridgeOptions bo;
  bo.seconds = seconds;
  bo.rt_priority = absl::GetFlag(FLAGS_rt_priority);
  bo.cpu = loop_cpu;
  bo.first_seq = 1000;
  bo.spin_margin = absl::GetFlag(FLAGS_spin_us) * 1e-6;
  dh::Bridge bridge(hand, &link, bo);
  std::atomic<bool> stop{false};
  dh::LoopSummary s = bridge.Run(stop);
  const dynsolid::SessionStats after = Stats(*stub, ref);
  link.Stop();
  std::printf("%s", s.Text().c_str());
  std::printf("CPUs: %s\n", others.c_str());

  const double step_rate =
      static_cast<double>(after.step() - before.step()) / std::max(1e-9, s.seconds);
  double contact_ms = -1;
  for (const auto& p : after.phases()) {
    if (p.name() == "contact") contact_ms = p.median_ms();
  }
  int64_t frames = 0;
  for (auto& w : watchers) frames += w->Counts().frames;
  if (watcher_process) frames += watcher_process->Finish();
  std::printf(
      "server: %.1f steps/s over the run (%.1f%% of real time), step %.3f ms median, "
      "p99 %.3f ms, contact phase %.3f ms median; watcher frames %ld (%s)\n",
      step_rate, 100.0 * step_rate * session.time_step(), after.step_ms_median(),
      after.step_ms_p99(), contact_ms, static_cast<long>(frames),
      watcher_process ? "in a process of their own" : "in this process");
  std::printf("\n| figure | measured | target |\n| --- | ---: | ---: |\n");
  std::printf("| loop period error p99 | %.1f us | <= 100 us |\n", s.period_error_p99_us);
  std::printf("| loop period error p99.9 | %.1f us | <= 250 us |\n", s.period_error_p999_us);
  std::printf("| loop period p50 / p99 / p99.9 / max | %.1f / %.1f / %.1f / %.1f us | |\n",
              s.period_p50_us, s.period_p99_us, s.period_p999_us, s.period_max_us);
  std::printf("| deadline misses (> %.0f us late or skipped) | %ld of %ld | |\n",
              s.miss_threshold_us, static_cast<long>(s.deadline_misses),
              static_cast<long>(s.ticks));
  std::printf(
      "| contact model refresh | %.1f Hz (server steps %.1f/s) | >= 200 Hz, the step "
      "rate |\n",
      s.model_refresh_hz, step_rate);
  std::printf("| contact model age p50 / p99 | %.2f / %.2f ms | |\n", s.model_age_p50_ms,
              s.model_age_p99_ms);
  std::printf(
      "| force computation per tick p50 / p99 / p99.9 / max | %.2f / %.2f / %.2f / %.2f "
      "us | <= 20 us |\n",
      s.compute_p50_us, s.compute_p99_us, s.compute_p999_us, s.compute_max_us);
  std::printf("| largest force step | %.3f N | <= %.1f N (the bound) |\n", s.largest_force_step_n,
              s.force_step_bound_n);
  std::printf("| safety ramps | %ld | |\n", static_cast<long>(s.safety_ramps));
  // Time the machine's hypervisor took from this VM's CPUs (/proc/stat
  // steal): a loop stalled while its vCPU was descheduled shows as a long
  // period (and a long compute time if it fell there).
  std::printf("| CPU steal during the run | %.0f ms | |\n", SumSteal() - steal0);
  if (!absl::GetFlag(FLAGS_json).empty()) {
    std::string json = s.Json();
    json.insert(json.rfind('}'), absl::StrFormat(",\n  \"server_steps_per_second\": %.2f,\n"
                                                 "  \"server_contact_ms\": %.4f\n",
                                                 step_rate, contact_ms));
    std::ofstream(absl::GetFlag(FLAGS_json)) << json;
  }
  for (auto& w : watchers) (void)w->Stop();
  return 0;
}
