// watch_bench: a session's simulation step rate with no watchers and with
// N watchers (default 64 at 60 Hz), and what the frames cost on the wire.
//
//   watch_bench [--server_binary PATH] [--server_flags "--stream_nice=10"]
//               [--scene block3] [--levels L]
//               [--watchers 64] [--hz 60] [--seconds 5] [--rounds 2]
//               [--decode=true] [--bench_nice 0]
//               [--shake_ms 250] [--shake_newtons 2e4]
//
// Starts dynsolid-server (port 0), creates a running session of the scene,
// and keeps the solid moving by swapping a sideways point force on its top
// every --shake_ms (otherwise the block3 scene sits still and every delta
// is empty). Then alternates, --rounds times, a phase without watchers and
// a phase with --watchers Watch streams, each on its own connection and
// decoding every frame (SurfaceDecoder), and ends with one more phase
// without watchers; besides the means it prints each watched phase's rate
// against the mean of the two unwatched phases around it, and their median. Step counts come from the
// server's GetStats (step, at the start and end of each phase); rates are
// steps per second of wall time. Prints figures; asserts nothing about time.
//
// Delta bytes are compared with what the same frames would take as raw
// float32 positions (12 bytes per surface vertex).
//
// The watchers stand for remote machines but run on the server's cores:
// each receives every frame's bytes and parses the Frame; with --decode
// (default) it also applies it to a SurfaceDecoder (the client's full
// work). --bench_nice lowers the priority of the whole benchmark process
// (after the server is started, which keeps its own), so that what the
// watchers cost competes less with the server; the bench's CPU is reported
// either way. Server CPU per frame: the server CPU of a watched phase less
// what its steps cost in the unwatched phases (per step), divided by the
// frames the watchers received. Streaming CPU: the CPU of the server's
// threads named "encode" and of gRPC's threads (names from
// /proc/PID/task/TID/comm) in the phase, divided likewise; the rest is the
// simulation (threads that ended during a phase count as the rest).
#include <sys/prctl.h>
#include <sys/resource.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "clients/lib/session_runner.h"
#include "clients/lib/surface.h"
#include "dynsolid/service.grpc.pb.h"

ABSL_FLAG(std::string, server_binary, "",
          "dynsolid-server to start (default: ../server/dynsolid-server next to this binary)");
ABSL_FLAG(std::string, scene, "block3", "Built-in scene");
ABSL_FLAG(int, levels, -1, "Subdivision levels (-1: the scene's)");
ABSL_FLAG(int, watchers, 64, "Watch streams in the loaded phases");
ABSL_FLAG(double, hz, 60, "Frames per second each watcher asks for");
ABSL_FLAG(double, seconds, 5, "Length of each measured phase, seconds");
ABSL_FLAG(int, rounds, 2, "Pairs of (no watchers, watchers) phases");
ABSL_FLAG(bool, decode, true, "Watchers decode every frame (as a real client does)");
ABSL_FLAG(int, shake_ms, 250, "Swap the sideways force every this many ms (0: no force)");
ABSL_FLAG(double, shake_newtons, 2e4, "Magnitude of the sideways force, newtons");
ABSL_FLAG(std::string, server_log, "/dev/null", "Where the server's log (stderr) goes");
ABSL_FLAG(std::string, server_flags, "",
          "More flags for the server, separated by spaces (e.g. --stream_nice=0)");
ABSL_FLAG(int, bench_nice, 0,
          "Nice value added to this benchmark's own threads (the watchers and their gRPC "
          "threads), 0..19; the server keeps its own");

namespace {

using Clock = std::chrono::steady_clock;
namespace dc = dynsolid::client;

std::string DefaultServerBinary(const char* argv0) {
  std::error_code ec;
  std::filesystem::path self = std::filesystem::canonical("/proc/self/exe", ec);
  if (ec) self = argv0;
  return (self.parent_path().parent_path() / "server" / "dynsolid-server").string();
}

// The server child process.
class ServerProcess {
 public:
  ServerProcess(const std::string& binary, int max_watchers, const std::string& log,
                const std::vector<std::string>& extra) {
    int out[2];
    if (::pipe(out) != 0) return;
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {
      // The server ends with the benchmark, however the benchmark ends.
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != parent) ::_exit(127);
      ::dup2(out[1], 1);
      const int err = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600);
      if (err >= 0) ::dup2(err, 2);
      ::close(out[0]);
      const std::string watchers = absl::StrCat("--max_watchers_per_session=", max_watchers);
      std::vector<std::string> args = {binary, "--listen=127.0.0.1:0", watchers,
                                       "--max_watch_hz=1000"};
      args.insert(args.end(), extra.begin(), extra.end());
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(binary.c_str(), argv.data());
      ::_exit(127);
    }
    ::close(out[1]);
    std::string line;
    char c;
    while (::read(out[0], &c, 1) == 1 && c != '\n') line.push_back(c);
    ::close(out[0]);
    const std::string prefix = "listening on ";
    if (line.rfind(prefix, 0) == 0) address_ = line.substr(prefix.size());
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
  }
  const std::string& address() const { return address_; }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  std::string address_;
};

struct WatcherResult {
  int64_t frames = 0, keyframes = 0, skipped = 0;
  int64_t delta_frames = 0, delta_bytes = 0, delta_raw_bytes = 0, moved = 0;
  int64_t key_bytes = 0, key_raw_bytes = 0;
  int64_t decode_errors = 0;
  std::string error;
};

// One Watch stream on its own connection, until stopped.
class BenchWatcher {
 public:
  BenchWatcher(const std::string& address, const dynsolid::SessionRef& ref, double hz,
               bool decode) {
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // a connection of its own
    args.SetMaxReceiveMessageSize(64 << 20);
    auto channel = grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
    stub_ = dynsolid::Sessions::NewStub(channel);
    dynsolid::WatchRequest request;
    *request.mutable_session() = ref;
    request.set_rate_hz(hz);
    thread_ = std::thread([this, request, decode] {
      auto reader = stub_->Watch(&context_, request);
      dynsolid::Frame frame;
      dc::SurfaceDecoder decoder;
      int64_t vertices = 0;
      while (reader->Read(&frame)) {
        absl::MutexLock lock(&mu_);
        ++r_.frames;
        r_.skipped += frame.skipped();
        const int64_t bytes = static_cast<int64_t>(frame.ByteSizeLong());
        if (frame.has_keyframe()) {
          ++r_.keyframes;
          vertices = frame.keyframe().vertex_count();
          r_.key_bytes += bytes;
          r_.key_raw_bytes += 12 * vertices;
        } else {
          ++r_.delta_frames;
          r_.delta_bytes += bytes;
          r_.delta_raw_bytes += 12 * vertices;
          r_.moved += frame.delta().moved();
        }
        if (decode && !decoder.Apply(frame).ok()) ++r_.decode_errors;
      }
      const grpc::Status s = reader->Finish();
      absl::MutexLock lock(&mu_);
      if (!s.ok() && s.error_code() != grpc::StatusCode::CANCELLED) r_.error = s.error_message();
    });
  }
  ~BenchWatcher() {
    context_.TryCancel();
    if (thread_.joinable()) thread_.join();
  }
  WatcherResult Take() {
    absl::MutexLock lock(&mu_);
    return r_;
  }

 private:
  std::unique_ptr<dynsolid::Sessions::Stub> stub_;
  grpc::ClientContext context_;
  absl::Mutex mu_;
  WatcherResult r_ ABSL_GUARDED_BY(mu_);
  std::thread thread_;
};

dynsolid::SessionStats Stats(dynsolid::Sessions::Stub& stub, const dynsolid::SessionRef& ref) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  dynsolid::SessionStats stats;
  const grpc::Status s = stub.GetStats(&context, ref, &stats);
  if (!s.ok()) {
    std::cerr << "watch_bench: GetStats: " << s.error_message() << "\n";
    std::exit(1);
  }
  return stats;
}

// CPU seconds (user + system) a process has used so far, from
// /proc/PID/stat (fields 14 and 15, in clock ticks).
std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return absl::StrCat(a, " ", b, " ", c);
}

double CpuSecondsOf(const std::string& stat_path) {
  std::ifstream in(stat_path);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t close = text.rfind(')');
  if (close == std::string::npos) return 0;
  std::istringstream fields(text.substr(close + 2));
  std::string f;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && fields >> f; ++i) {
    if (i == 14) utime = std::stod(f);
    if (i == 15) stime = std::stod(f);
  }
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

double CpuSeconds(pid_t pid) { return CpuSecondsOf(absl::StrCat("/proc/", pid, "/stat")); }

// Whether a server thread streams frames (the encoders and gRPC's threads).
bool IsStreamingThread(const std::string& comm) {
  for (const char* prefix : {"encode", "nexting", "default-exec", "grpc", "resolver", "event_engine", "timer_manager"}) {
    if (comm.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

// CPU seconds the server's streaming threads have used so far.
double StreamingCpuSeconds(pid_t pid) {
  double total = 0;
  std::error_code ec;
  for (const auto& task :
       std::filesystem::directory_iterator(absl::StrCat("/proc/", pid, "/task"), ec)) {
    std::ifstream comm_file(task.path() / "comm");
    std::string comm;
    std::getline(comm_file, comm);
    if (IsStreamingThread(comm)) total += CpuSecondsOf((task.path() / "stat").string());
  }
  return total;
}

struct Phase {
  int watchers = 0;
  int64_t steps = 0;
  double seconds = 0;
  double step_ms_median = 0, step_ms_p99 = 0;
  int64_t overruns = 0;
  double server_cpu = 0, bench_cpu = 0;  // CPU seconds used in the phase
  double stream_cpu = 0;                  // of server_cpu: the streaming threads
  std::vector<WatcherResult> results;
  double rate() const { return seconds > 0 ? steps / seconds : 0; }
};

// Keeps the solid moving: swaps a sideways force on the top every
// shake_ms, on a thread of its own until Stop.
class Shaker {
 public:
  explicit Shaker(dc::CommandChannel& commands) : commands_(commands) {
    thread_ = std::thread([this] { Run(); });
  }
  void Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  ~Shaker() { Stop(); }

 private:
  void Run() {
    const int ms = absl::GetFlag(FLAGS_shake_ms);
    if (ms <= 0) return;
    double sign = 1;
    uint64_t previous = 0;
    while (!stop_) {
      dynsolid::Command add;
      auto* f = add.mutable_add_point_force();
      f->mutable_position()->set_x(1.5);
      f->mutable_position()->set_y(1.5);
      f->mutable_position()->set_z(3);
      f->mutable_force()->set_x(sign * absl::GetFlag(FLAGS_shake_newtons));
      auto seq = commands_.Send(add, "shake");
      if (previous != 0) {
        auto old = commands_.Wait(previous, absl::Seconds(10));
        if (old.ok() && old->code() == 0) {
          dynsolid::Command remove;
          remove.mutable_remove_load()->set_load_id(old->load_id());
          (void)commands_.Send(remove, "unshake");
        }
      }
      previous = seq.ok() ? *seq : 0;
      sign = -sign;
      std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    }
  }
  dc::CommandChannel& commands_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// What a phase runs against: the server, its session and the watchers' rate.
struct Target {
  const ServerProcess* server;
  dynsolid::Sessions::Stub* stub;
  dynsolid::SessionRef ref;
  double hz;
  std::chrono::duration<double> length;
};

// `watchers` watchers for one phase: a second to settle, then the phase's
// length measured (steps, CPU, frames).
Phase RunPhase(const Target& t, int watchers) {
  const ServerProcess& server = *t.server;
  Phase p;
  p.watchers = watchers;
  std::vector<std::unique_ptr<BenchWatcher>> ws;
  for (int i = 0; i < watchers; ++i) {
    ws.push_back(std::make_unique<BenchWatcher>(server.address(), t.ref, t.hz,
                                                absl::GetFlag(FLAGS_decode)));
  }
  std::this_thread::sleep_for(std::chrono::seconds(1));  // settle: keyframes, connections
  std::vector<WatcherResult> before;
  for (auto& w : ws) before.push_back(w->Take());
  const double server_cpu0 = CpuSeconds(server.pid()), bench_cpu0 = CpuSeconds(::getpid());
  const double stream_cpu0 = StreamingCpuSeconds(server.pid());
  const dynsolid::SessionStats s0 = Stats(*t.stub, t.ref);
  const Clock::time_point t0 = Clock::now();
  std::this_thread::sleep_for(t.length);
  const dynsolid::SessionStats s1 = Stats(*t.stub, t.ref);
  const Clock::time_point t1 = Clock::now();
  p.server_cpu = CpuSeconds(server.pid()) - server_cpu0;
  p.stream_cpu = StreamingCpuSeconds(server.pid()) - stream_cpu0;
  p.bench_cpu = CpuSeconds(::getpid()) - bench_cpu0;
  for (size_t i = 0; i < ws.size(); ++i) {
    WatcherResult a = ws[i]->Take();
    const WatcherResult& b = before[i];
    a.frames -= b.frames;
    a.keyframes -= b.keyframes;
    a.skipped -= b.skipped;
    a.delta_frames -= b.delta_frames;
    a.delta_bytes -= b.delta_bytes;
    a.delta_raw_bytes -= b.delta_raw_bytes;
    a.moved -= b.moved;
    a.key_bytes -= b.key_bytes;
    a.key_raw_bytes -= b.key_raw_bytes;
    p.results.push_back(a);
  }
  p.steps = s1.step() - s0.step();
  p.seconds = std::chrono::duration<double>(t1 - t0).count();
  p.step_ms_median = s1.step_ms_median();
  p.step_ms_p99 = s1.step_ms_p99();
  p.overruns = s1.overruns() - s0.overruns();
  ws.clear();
  return p;
}

// The phases' sums that the summary lines read.
struct Totals {
  double rate0 = 0, rate_n = 0;
  int n0 = 0, nn = 0;
  int64_t all_delta = 0, all_raw = 0, all_key = 0, all_key_raw = 0, errors = 0;
  int64_t frames_n = 0, skipped_n = 0;
  double seconds_n = 0, bench_cpu_n = 0, stream_cpu_n = 0, stream_cpu0 = 0;
};

// The table, a row per phase; returns the sums (rates not yet averaged).
Totals PrintPhases(const std::vector<Phase>& phases, double h) {
  Totals t;
  std::cout << "\n| phase | watchers | steps | seconds | steps/s | % of real time | step ms median "
               "| step ms p99 | overruns | server CPU s | of which streaming | server CPU ms/step | bench CPU s "
               "| frames/watcher (min..max) | frames/s/watcher | skipped/s/watcher "
               "| keyframes | delta bytes / raw float32 | moved/delta |\n"
               "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
               "| ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |\n";
  for (size_t i = 0; i < phases.size(); ++i) {
    const Phase& p = phases[i];
    int64_t fmin = INT64_MAX, fmax = 0, frames = 0, skipped = 0, keys = 0, delta = 0, raw = 0,
            moved = 0, deltas = 0;
    for (const WatcherResult& w : p.results) {
      fmin = std::min(fmin, w.frames);
      fmax = std::max(fmax, w.frames);
      frames += w.frames;
      skipped += w.skipped;
      keys += w.keyframes;
      delta += w.delta_bytes;
      raw += w.delta_raw_bytes;
      moved += w.moved;
      deltas += w.delta_frames;
      t.all_key += w.key_bytes;
      t.all_key_raw += w.key_raw_bytes;
      t.errors += w.decode_errors;
      if (!w.error.empty()) std::cerr << "watcher error: " << w.error << "\n";
    }
    t.all_delta += delta;
    t.all_raw += raw;
    const double nw = std::max<size_t>(p.results.size(), 1);
    if (p.watchers == 0) {
      t.rate0 += p.rate();
      ++t.n0;
      t.stream_cpu0 += p.stream_cpu;
    } else {
      t.rate_n += p.rate();
      ++t.nn;
      t.frames_n += frames;
      t.skipped_n += skipped;
      t.seconds_n += p.seconds;
      t.bench_cpu_n += p.bench_cpu;
      t.stream_cpu_n += p.stream_cpu;
    }
    std::cout << absl::StrFormat(
        "| %d | %d | %d | %.2f | %.1f | %.1f %% | %.3f | %.3f | %d | %.2f | %.2f | %.2f | %.2f "
        "| %s | %s | %s | %d | %s | %s |\n",
        i + 1, p.watchers, p.steps, p.seconds, p.rate(), 100 * p.rate() * h, p.step_ms_median,
        p.step_ms_p99, p.overruns, p.server_cpu, p.stream_cpu,
        p.steps > 0 ? 1000 * p.server_cpu / p.steps : 0.0,
        p.bench_cpu, p.watchers ? absl::StrFormat("%.1f (%d..%d)", frames / nw, fmin, fmax) : "-",
        p.watchers ? absl::StrFormat("%.1f", frames / nw / p.seconds) : "-",
        p.watchers ? absl::StrFormat("%.1f", skipped / nw / p.seconds) : "-", keys,
        raw > 0 ? absl::StrFormat("%.1f %%", 100.0 * delta / raw) : "-",
        deltas > 0 ? absl::StrFormat("%.0f", double(moved) / deltas) : "-");
  }
  return t;
}

// The summary lines under the table: step rates with and without
// watchers (paired per round), CPU per step and per frame, frame sizes.
void PrintSummary(const std::vector<Phase>& phases, Totals t, double h, int n_watchers, double hz,
                  const std::string& load_before) {
  t.rate0 /= std::max(t.n0, 1);
  t.rate_n /= std::max(t.nn, 1);
  // Paired: each watched phase against the mean of the unwatched phases
  // just before and after it (slow changes of the machine's load cancel).
  std::vector<double> paired;
  for (size_t i = 1; i + 1 < phases.size(); i += 2) {
    const double base = (phases[i - 1].rate() + phases[i + 1].rate()) / 2;
    if (base > 0) paired.push_back(100.0 * (phases[i].rate() - base) / base);
  }
  std::sort(paired.begin(), paired.end());
  std::string paired_text;
  for (double x : paired) paired_text += absl::StrFormat(" %+.1f", x);
  const double paired_median =
      paired.empty() ? 0.0
                     : (paired[(paired.size() - 1) / 2] + paired[paired.size() / 2]) / 2;
  double cpu0 = 0, cpu_n = 0;
  int64_t steps0 = 0, steps_n = 0;
  for (const Phase& p : phases) {
    (p.watchers == 0 ? cpu0 : cpu_n) += p.server_cpu;
    (p.watchers == 0 ? steps0 : steps_n) += p.steps;
  }
  const double per_step0 = steps0 ? cpu0 / steps0 : 0.0;
  const double frame_cpu = cpu_n - per_step0 * static_cast<double>(steps_n);
  std::cout << absl::StrFormat(
      "server CPU per sim step: %.2f ms without watchers, %.2f ms with %d watchers; server CPU "
      "for frames: %.1f us per frame received by difference (%.3f cores), %.1f us measured on "
      "the streaming threads (%.3f cores; %.3f s in the unwatched phases); bench CPU %.3f "
      "cores; %d cores online; load average %s before, %s after\n",
      1000 * per_step0, steps_n ? 1000 * cpu_n / steps_n : 0.0, n_watchers,
      t.frames_n ? 1e6 * frame_cpu / t.frames_n : 0.0, t.seconds_n > 0 ? frame_cpu / t.seconds_n : 0.0,
      t.frames_n ? 1e6 * t.stream_cpu_n / t.frames_n : 0.0,
      t.seconds_n > 0 ? t.stream_cpu_n / t.seconds_n : 0.0, t.stream_cpu0,
      t.seconds_n > 0 ? t.bench_cpu_n / t.seconds_n : 0.0, ::sysconf(_SC_NPROCESSORS_ONLN), load_before,
      LoadAverage());
  const double nwatch = std::max(n_watchers, 1);
  std::cout << absl::StrFormat(
      "\nsim step rate: %.1f steps/s without watchers (%.1f %% of real time), %.1f with %d "
      "watchers at %g Hz: %+.2f %% (target: within 5 %%); paired per round (%%, sorted):%s, "
      "median %+.1f %%; each watcher received %.1f frames/s and missed %.1f (skipped by the "
      "server)\n",
      t.rate0, 100 * t.rate0 * h, t.rate_n, n_watchers, hz,
      t.rate0 > 0 ? 100.0 * (t.rate_n - t.rate0) / t.rate0 : 0.0, paired_text, paired_median,
      t.seconds_n > 0 ? t.frames_n / nwatch / t.seconds_n : 0.0,
      t.seconds_n > 0 ? t.skipped_n / nwatch / t.seconds_n : 0.0);
  std::cout << absl::StrFormat(
      "delta frames: %d bytes for frames worth %d bytes as raw float32 positions: %.2f %% "
      "(target: <= 25 %%); keyframes: %.1f %% of raw; decode errors: %d\n",
      t.all_delta, t.all_raw, t.all_raw > 0 ? 100.0 * t.all_delta / t.all_raw : 0.0,
      t.all_key_raw > 0 ? 100.0 * t.all_key / t.all_key_raw : 0.0, t.errors);
}

}  // namespace

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  std::string binary = absl::GetFlag(FLAGS_server_binary);
  if (binary.empty()) binary = DefaultServerBinary(argv[0]);
  const int n_watchers = absl::GetFlag(FLAGS_watchers);
  const double hz = absl::GetFlag(FLAGS_hz);
  const auto phase_length = std::chrono::duration<double>(absl::GetFlag(FLAGS_seconds));
  std::vector<std::string> extra;
  {
    std::istringstream in(absl::GetFlag(FLAGS_server_flags));
    for (std::string f; in >> f;) extra.push_back(f);
  }
  const std::string load_before = LoadAverage();
  ServerProcess server(binary, std::max(n_watchers, 1), absl::GetFlag(FLAGS_server_log), extra);
  if (server.address().empty()) {
    std::cerr << "watch_bench: " << binary << " did not start\n";
    return 1;
  }
  // From here on every thread of this process inherits the lowered
  // priority (the server was forked before). The server and the benchmark
  // stay in one session (one scheduling autogroup), so nice values order
  // the server's simulation, its streaming threads and these watchers.
  if (const int nice = absl::GetFlag(FLAGS_bench_nice); nice > 0) {
    if (::setpriority(PRIO_PROCESS, 0, std::min(19, ::getpriority(PRIO_PROCESS, 0) + nice)) != 0) {
      std::cerr << "watch_bench: setpriority failed; the benchmark keeps its priority\n";
    }
  }
  std::cout << "server flags:";
  for (const std::string& f : extra) std::cout << " " << f;
  std::cout << (extra.empty() ? " (defaults)" : "") << "; benchmark nice +"
            << absl::GetFlag(FLAGS_bench_nice) << "; watchers "
            << (absl::GetFlag(FLAGS_decode) ? "parse and decode every frame"
                                             : "parse every frame (no decoding)")
            << "\n";
  dc::ChannelOptions channel_options;
  channel_options.address = server.address();
  const dc::ChannelFactory channels = dc::ChannelFactoryFor(channel_options);
  auto stub = dynsolid::Sessions::NewStub(channels());

  dynsolid::CreateSessionRequest create;
  create.set_builtin_scene(absl::GetFlag(FLAGS_scene));
  if (absl::GetFlag(FLAGS_levels) >= 0) create.set_levels_override(absl::GetFlag(FLAGS_levels));
  dynsolid::Session session;
  {
    grpc::ClientContext context;
    const grpc::Status s = stub->CreateSession(&context, create, &session);
    if (!s.ok()) {
      std::cerr << "watch_bench: CreateSession: " << s.error_message() << "\n";
      return 1;
    }
  }
  dynsolid::SessionRef ref;
  ref.set_id(session.id());
  ref.set_token(session.token());
  const dynsolid::SolidStats& solid = session.stats();
  std::cout << absl::StrFormat(
      "scene %s: %d cells, %d surface vertices, %d surface quads, h = %g s (real time: %g "
      "steps/s at most)\n",
      session.scene_name(), solid.cells(), solid.boundary_vertices(), solid.boundary_faces(),
      session.time_step(), 1 / session.time_step());

  dc::CommandChannel commands(channels, ref, "watch_bench");
  Shaker shaker(commands);

  const Target target{&server, stub.get(), ref, hz, phase_length};
  auto run_phase = [&](int watchers) { return RunPhase(target, watchers); };

  std::vector<Phase> phases;
  for (int r = 0; r < absl::GetFlag(FLAGS_rounds); ++r) {
    phases.push_back(run_phase(0));
    phases.push_back(run_phase(n_watchers));
  }
  phases.push_back(run_phase(0));  // every watched phase between two unwatched ones
  shaker.Stop();
  (void)commands.Close(absl::Seconds(10));

  const double h = session.time_step();
  const Totals totals = PrintPhases(phases, h);
  PrintSummary(phases, totals, h, n_watchers, hz, load_before);
  return 0;
}
