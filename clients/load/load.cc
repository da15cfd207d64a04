#include "clients/load/load.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <mutex>
#include <random>
#include <thread>

#include <unistd.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "clients/lib/channel.h"
#include "clients/lib/command_channel.h"
#include "clients/lib/stats.h"
#include "clients/lib/watcher.h"
#include "clients/load/mix.h"
#include "clients/load/server_process.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::load {
namespace {

using Clock = std::chrono::steady_clock;
using client::ChannelFactory;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

std::string CodeName(int code) {
  static const char* kNames[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED", "NOT_FOUND", "ALREADY_EXISTS",
                                 "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
                                 "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL",
                                 "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  return code >= 0 && code <= 16 ? kNames[code] : absl::StrCat("CODE_", code);
}

Percentiles Summarize(std::vector<double> v) {
  Percentiles p;
  p.count = static_cast<int64_t>(v.size());
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  p.p50 = client::Percentile(v, 0.5);
  p.p99 = client::Percentile(v, 0.99);
  p.p999 = client::Percentile(v, 0.999);
  p.max = v.back();
  return p;
}

// The command's kind as its field name ("add_point_force"; "none" unset).
std::string KindName(const Command& c) {
  const google::protobuf::FieldDescriptor* f =
      Command::descriptor()->FindFieldByNumber(c.kind_case());
  return f != nullptr ? f->name() : "none";
}

// Whether a command never builds a solid on the server: not a paint, an
// edit, an unfix, an undo or a redo (those may build for tens to hundreds
// of ms, and their command is visible only after).
bool BuildsNothing(const Command& c) {
  switch (c.kind_case()) {
    case Command::kPaintMaterial:
    case Command::kEdit:
    case Command::kUnfix:
    case Command::kUndo:
    case Command::kRedo:
      return false;
    default:
      return true;
  }
}

struct ClientResult {
  std::vector<client::CommandRecord> records;
  std::vector<std::pair<int64_t, Clock::time_point>> frames;
  client::WatcherCounts watch;
  int reconnects = 0;
  std::vector<std::string> problems;
  std::map<std::string, int64_t> fault_codes;
};

// The client's own loads and drags (by the seq that made them).
struct Owned {
  std::vector<uint64_t> loads, drags, fixes;
  std::vector<std::pair<uint64_t, int>> curves;  // seq, points
};

class LoadRun {
 public:
  explicit LoadRun(const Options& o) : o_(o) {}

  absl::StatusOr<Report> Run();

 private:
  // Channels to the server given, or, for a session, to the replica that
  // owns it (Session.address; later redirects are followed by the streams).
  ChannelFactory Factory(const Session* session = nullptr) const {
    client::ChannelOptions c;
    c.address = address_;
    c.tls_root_certs = tls_roots_;
    c.max_message_bytes = 16 << 20;
    ChannelFactory f = client::ChannelFactoryFor(c);
    if (session != nullptr) f.Follow(*session);
    return f;
  }
  absl::StatusOr<Session> CreateSession();
  void Client(int i, const Session& session, const Box& box, ClientResult* out);
  void Malformed(int i, const Session& session, std::atomic<bool>* stop, ClientResult* out);
  Command Next(Mix& mix, client::CommandChannel& ch, Owned& owned);
  void Verify(const Session& session, const std::string& client_id,
              const std::vector<client::CommandRecord>& records, std::vector<std::string>* problems);
  void Log(const std::string& s) const {
    if (o_.verbose) std::fprintf(stderr, "dynsolid-load: %s\n", s.c_str());
  }

  const Options o_;
  std::string address_, tls_roots_;
  std::unique_ptr<ServerProcess> server_;
  std::atomic<int> restarts_{0};
  Clock::time_point start_;
};

absl::StatusOr<Session> LoadRun::CreateSession() {
  auto stub = Sessions::NewStub(Factory()());
  CreateSessionRequest r;
  r.set_builtin_scene(o_.scene);
  r.set_levels_override(o_.levels);
  Session s;
  const grpc::Status st = Retrying([&] {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    return stub->CreateSession(&c, r, &s);
  });
  if (!st.ok()) return client::ToAbslStatus(st, "CreateSession");
  return s;
}

SessionRef RefOf(const Session& s) {
  SessionRef r;
  r.set_id(s.id());
  r.set_token(s.token());
  return r;
}

Command LoadRun::Next(Mix& mix, client::CommandChannel& ch, Owned& owned) {
  Command c;
  // Answers the owner needs (a load id): the add was sent earlier; its
  // answer is normally long in.
  auto id_of = [&](uint64_t seq) -> int64_t {
    absl::StatusOr<CommandReply> r = ch.Wait(seq, absl::Seconds(30));
    if (!r.ok() || r->code() != 0) return -1;
    return r->has_load_id() ? r->load_id() : r->constraint_id();
  };
  // One of the client's own items, picked at random and forgotten: its id
  // (0 when it was refused, which the server then refuses by name).
  auto take = [&](std::vector<uint64_t>& seqs) -> int64_t {
    const size_t k = mix.Index(seqs.size());
    const int64_t id = id_of(seqs[k]);
    seqs.erase(seqs.begin() + static_cast<int64_t>(k));
    return std::max<int64_t>(id, 0);
  };
  enum { kForce, kRemove, kDrag, kMove, kRelease, kCurve, kPaint, kFix, kUnfix, kGravity,
         kPressure, kUndo, kRedo, kEdit };
  // A client keeps at most kMaxLoads forces and pressures of its own at
  // once (adding more, it removes them first): with 64 clients that is
  // still 256 loads on the solid.
  constexpr size_t kMaxLoads = 4;
  const bool room = owned.loads.size() < kMaxLoads;
  const std::vector<double> w = {
      room ? 18.0 : 0.0, owned.loads.empty() ? 0.0 : 10.0, owned.drags.size() < 2 ? 6.0 : 0.0,
      owned.drags.empty() && owned.curves.empty() ? 0.0 : 30.0,
      owned.drags.empty() ? 0.0 : 3.0, owned.curves.empty() ? 2.0 : 0.0, 1, 2,
      owned.fixes.empty() ? 0.0 : 2.0, 3, room ? 3.0 : 0.0, 2, 1, mix.edits() ? 0.5 : 0.0};
  const double size = mix.Size();
  // Sizes scale with a control cell (block3's 1 m cells: a 0.45 m brush),
  // forces with its face area (1 kN on block3, 10 N on the chair's 0.1 m
  // cells: a hand on a half-metre chair, not the kilonewtons that move a
  // 27 t block) and spring stiffnesses with its size.
  const double cell = mix.Cell();
  const double scale = cell * cell;
  const double spring = cell;
  switch (mix.Pick(w)) {
    case kForce: {
      PointForce* f = c.mutable_add_point_force();
      *f->mutable_position() = mix.Material();
      *f->mutable_force() = V(mix.Uniform(-1, 1) * 1e3 * scale, mix.Uniform(-1, 1) * 1e3 * scale, 0);
      return c;
    }
    case kRemove:
      c.mutable_remove_load()->set_load_id(take(owned.loads));
      return c;
    case kDrag: {
      Drag* d = c.mutable_drag();
      *d->mutable_material_point() = mix.Material();
      Vec3 t = d->material_point();
      t.set_z(t.z() + 0.05 * size);
      *d->mutable_target() = t;
      d->set_stiffness(5e3 * spring);
      return c;
    }
    case kMove: {
      const bool curve = owned.drags.empty();
      MoveDrag* m = c.mutable_move_drag();
      const uint64_t seq = curve ? owned.curves[0].first : owned.drags[mix.Index(owned.drags.size())];
      m->set_load_id(std::max<int64_t>(id_of(seq), 0));
      if (curve) {
        for (int k = 0; k < owned.curves[0].second; ++k) *m->add_targets() = mix.Inside(0.3);
      } else {
        *m->mutable_target() = mix.Inside(0.3);
      }
      return c;
    }
    case kRelease:
      c.mutable_remove_load()->set_load_id(take(owned.drags));
      return c;
    case kCurve: {
      CurveDrag* cd = c.mutable_curve();
      for (int k = 0; k < 2; ++k) {
        *cd->add_material_points() = mix.Material();
        *cd->add_targets() = mix.Inside();
      }
      cd->set_stiffness(2e3 * spring);
      cd->set_samples(4);
      return c;
    }
    case kPaint: {
      MaterialPaint* p = c.mutable_paint_material();
      *p->mutable_region()->mutable_sphere()->mutable_center() = mix.Material();
      p->mutable_region()->mutable_sphere()->set_radius(0.45 * cell);
      p->mutable_material()->set_young_modulus(mix.Uniform(1, 3) * 1e5);
      p->set_strength(0.5);
      return c;
    }
    case kFix: {
      Region* r = c.mutable_fix_region();
      const Vec3 centre = mix.Material();
      r->mutable_sphere()->mutable_center()->CopyFrom(centre);
      r->mutable_sphere()->set_radius(0.6 * cell);
      return c;
    }
    case kUnfix:
      c.mutable_unfix()->set_constraint_id(take(owned.fixes));
      return c;
    case kGravity:
      *c.mutable_set_gravity() = V(0, 0, -mix.Uniform(0, 9.81));
      return c;
    case kPressure: {
      Pressure* p = c.mutable_add_pressure();
      *p->mutable_region()->mutable_sphere()->mutable_center() = mix.Material();
      p->mutable_region()->mutable_sphere()->set_radius(0.9 * cell);
      p->set_pascals(mix.Uniform(-1, 1) * 500);
      return c;
    }
    case kUndo:
      c.mutable_undo();
      return c;
    case kRedo:
      c.mutable_redo();
      return c;
    case kEdit:
    default: {
      ExtrudeFaces* x = c.mutable_edit()->mutable_extrude_faces();
      Vec3 p = mix.Inside();
      p.set_z(size);  // the top
      *x->add_near() = p;
      x->set_distance(0.1 * size);
      return c;
    }
  }
}

void LoadRun::Client(int i, const Session& session, const Box& box, ClientResult* out) {
  const std::string id = absl::StrCat("load-", i);
  client::CommandChannelOptions co;
  co.reconnect_timeout = absl::Seconds(60);
  if (o_.faults.disconnect) co.break_every = 5 + i % 7;
  client::CommandChannel ch(Factory(&session), RefOf(session), id, co);
  std::mutex frames_mu;
  client::WatcherOptions wo;
  wo.rate_hz = o_.watch_hz;
  wo.client_id = id;  // its own commands' frames at once
  wo.reconnect_timeout = absl::Seconds(60);
  wo.on_frame = [&](int64_t step, Clock::time_point at) {
    std::lock_guard<std::mutex> l(frames_mu);
    out->frames.emplace_back(step, at);
  };
  client::Watcher watcher(Factory(&session), RefOf(session), wo);
  // A watcher that never reads (fault): the server must not wait for it.
  std::unique_ptr<grpc::ClientContext> stalled_context;
  std::unique_ptr<grpc::ClientReader<Frame>> stalled;
  std::unique_ptr<Sessions::Stub> stalled_stub;
  if (o_.faults.stop_reading && i % 2 == 0) {
    stalled_stub = Sessions::NewStub(Factory(&session)());
    stalled_context = std::make_unique<grpc::ClientContext>();
    WatchRequest wr;
    *wr.mutable_session() = RefOf(session);
    wr.set_rate_hz(60);
    stalled = stalled_stub->Watch(stalled_context.get(), wr);
  }
  Mix mix(o_.seed * 1000003 + static_cast<uint64_t>(i), box, o_.edits);
  Owned owned;
  const auto end = start_ + std::chrono::duration<double>(o_.seconds);
  const auto period = std::chrono::duration<double>(1.0 / o_.rate);
  auto next = start_ + std::chrono::duration_cast<Clock::duration>(period * (i % 10) / 10.0);
  int64_t sent = 0;
  while (Clock::now() < end && (o_.max_commands == 0 || sent < o_.max_commands)) {
    std::this_thread::sleep_until(next);
    next += std::chrono::duration_cast<Clock::duration>(period);
    const Command c = Next(mix, ch, owned);
    absl::StatusOr<uint64_t> seq = ch.Send(c, std::to_string(sent));
    if (!seq.ok()) {
      out->problems.push_back(absl::StrCat(id, ": send failed: ", seq.status().ToString()));
      break;
    }
    ++sent;
    switch (c.kind_case()) {
      case Command::kAddPointForce:
      case Command::kAddPressure:
        owned.loads.push_back(*seq);
        break;
      case Command::kDrag:
        owned.drags.push_back(*seq);
        break;
      case Command::kCurve:
        owned.curves.emplace_back(*seq, c.curve().material_points_size());
        break;
      case Command::kFixRegion:
        owned.fixes.push_back(*seq);
        break;
      default:
        break;
    }
    // A curve acts for a while, then goes.
    if (c.kind_case() == Command::kMoveDrag && owned.drags.empty() && !owned.curves.empty() &&
        mix.Uniform(0, 1) < 0.1) {
      owned.curves.clear();
    }
  }
  if (absl::Status s = ch.WaitAll(absl::Seconds(90)); !s.ok()) {
    out->problems.push_back(absl::StrCat(id, ": not every command was answered: ", s.ToString()));
  }
  (void)ch.Close(absl::Seconds(10));
  if (stalled_context != nullptr) stalled_context->TryCancel();
  (void)watcher.Stop();
  out->records = ch.Records();
  out->reconnects = ch.reconnects();
  out->watch = watcher.Counts();
  if (ch.extra_answers() > 0) {
    out->problems.push_back(absl::StrCat(id, ": ", ch.extra_answers(),
                                         " answers to already answered commands"));
  }
}

// Malformed traffic on its own streams and client ids: non-finite values,
// an oversized message, a wrong token. Each must be refused with a status
// and change nothing for the others.
void LoadRun::Malformed(int i, const Session& session, std::atomic<bool>* stop,
                        ClientResult* out) {
  auto stub = Sessions::NewStub(Factory(&session)());
  uint64_t seq = 0;
  int round = 0;
  while (!stop->load()) {
    grpc::ClientContext context;
    auto rw = stub->Commands(&context);
    CommandRequest r;
    *r.mutable_session() = RefOf(session);
    r.set_client_id(absl::StrCat("bad-", i));
    r.set_seq(++seq);
    switch (round++ % 3) {
      case 0: {  // non-finite
        PointForce* f = r.mutable_command()->mutable_add_point_force();
        *f->mutable_position() = V(NAN, 0, 1);
        *f->mutable_force() = V(1, 0, 0);
        break;
      }
      case 1: {  // oversized: above the server's 4 MiB message limit
        Region* reg = r.mutable_command()->mutable_fix_region();
        for (int k = 0; k < 2'500'000; ++k) reg->add_control_cells(k);
        break;
      }
      default:  // a wrong token
        r.mutable_session()->set_token("not-the-token");
        r.mutable_command()->mutable_pause();
        break;
    }
    CommandReply reply;
    static const char* kKinds[] = {"non-finite", "oversized", "wrong token"};
    const char* kind = kKinds[(round - 1) % 3];
    std::string outcome;
    if (rw->Write(r) && rw->Read(&reply)) {
      outcome = CodeName(reply.code());
    }
    rw->WritesDone();
    const grpc::Status st = rw->Finish();
    if (outcome.empty()) outcome = CodeName(st.error_code());
    ++out->fault_codes[absl::StrCat("malformed ", kind, ": ", outcome)];
    if (outcome == "OK") {
      out->problems.push_back(absl::StrCat("bad-", i, " seq ", seq, ": a malformed command was accepted"));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

void LoadRun::Verify(const Session& session, const std::string& client_id,
                     const std::vector<client::CommandRecord>& records,
                     std::vector<std::string>* problems) {
  auto stub = Sessions::NewStub(Factory(&session)());
  CommandLogRequest r;
  *r.mutable_session() = RefOf(session);
  r.set_client_id(client_id);
  CommandLog log;
  const grpc::Status st = Retrying([&] {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    return stub->GetCommandLog(&c, r, &log);
  });
  if (!st.ok()) {
    problems->push_back(absl::StrCat(client_id, ": GetCommandLog: ", st.error_message()));
    return;
  }
  for (std::string& p : CheckAgainstJournal(client_id, records, log)) problems->push_back(std::move(p));
}

absl::StatusOr<Report> LoadRun::Run() {
  Report rep;
  rep.options = o_;
  const auto wall0 = Clock::now();
  std::string temp_dir;
  if (!o_.tls_ca.empty()) {
    std::ifstream f(o_.tls_ca);
    tls_roots_.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    if (tls_roots_.empty()) return absl::InvalidArgumentError(absl::StrCat("--tls_ca: cannot read ", o_.tls_ca));
  }
  if (!o_.server_binary.empty()) {
    std::string dir = o_.data_dir;
    if (dir.empty()) {
      char tmpl[] = "/tmp/dynsolid_load_XXXXXX";
      if (mkdtemp(tmpl) == nullptr) return absl::InternalError("mkdtemp failed");
      dir = temp_dir = tmpl;
    }
    server_ = std::make_unique<ServerProcess>(o_.server_binary, dir, o_.server_args);
    if (absl::Status s = server_->Start(); !s.ok()) return s;
    address_ = server_->address();
    Log(absl::StrCat("started ", o_.server_binary, " on ", address_, " with --data_dir ", dir));
  } else {
    address_ = o_.server;
    if (o_.faults.restart) {
      return absl::InvalidArgumentError("--faults=restart needs --server_binary (a server this tool starts)");
    }
  }

  // Sessions: one shared, or one per client.
  std::vector<Session> sessions;
  for (int k = 0; k < (o_.shared ? 1 : o_.clients); ++k) {
    absl::StatusOr<Session> s = CreateSession();
    if (!s.ok()) return s.status();
    sessions.push_back(*s);
  }
  for (const Session& s : sessions) ++rep.sessions_per_replica[s.replica()];
  absl::StatusOr<Box> box = RestBox(*Sessions::NewStub(Factory(&sessions[0])()), RefOf(sessions[0]));
  if (!box.ok()) return box.status();
  box->inside = MaterialPoints(*Sessions::NewStub(Factory(&sessions[0])()), RefOf(sessions[0]),
                               *box, 256, o_.seed);
  Log(absl::StrCat(box->inside.size(), " material points inside the solid for the commands"));
  auto stats = [&](const Session& s) {
    SessionStats st;
    auto stub = Sessions::NewStub(Factory(&s)());
    (void)Retrying([&] {
      grpc::ClientContext c;
      c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
      return stub->GetStats(&c, RefOf(s), &st);
    });
    return st;
  };
  // The unloaded step rate: a second and a half with nobody connected.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  rep.unloaded_steps_per_second = stats(sessions[0]).steps_per_second();
  const SessionStats before = stats(sessions[0]);

  // CPU and memory of a server started here.
  std::atomic<bool> sampling{true};
  std::thread sampler;
  start_ = Clock::now();
  if (server_ != nullptr) {
    sampler = std::thread([&] {
      double last_cpu = -1;
      auto last_t = Clock::now();
      while (sampling.load()) {
        double cpu = 0;
        long rss = 0;
        const auto now = Clock::now();
        if (server_->Sample(&cpu, &rss)) {
          const double dt = std::chrono::duration<double>(now - last_t).count();
          const double pct = last_cpu >= 0 && dt > 0 && cpu >= last_cpu ? 100 * (cpu - last_cpu) / dt : 0;
          if (last_cpu >= 0) {
            rep.server_samples.push_back({std::chrono::duration<double>(now - start_).count(), pct,
                                          static_cast<double>(rss)});
          }
          last_cpu = cpu;
          last_t = now;
          rep.server_rss_max_kb = std::max<int64_t>(rep.server_rss_max_kb, rss);
        } else {
          last_cpu = -1;  // restarting
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(250));
      }
    });
  }

  const pid_t server_pid = server_ != nullptr ? server_->pid() : 0;
  const CpuSnapshot server_cpu0 = TakeCpuSnapshot(server_pid);
  const CpuSnapshot tool_cpu0 = TakeCpuSnapshot(getpid());

  std::vector<ClientResult> results(o_.clients);
  std::vector<std::thread> threads;
  for (int i = 0; i < o_.clients; ++i) {
    threads.emplace_back([&, i] {
      Client(i, sessions[o_.shared ? 0 : i], *box, &results[i]);
    });
  }
  // Faults beside the clients.
  std::atomic<bool> stop_faults{false};
  std::vector<ClientResult> fault_results(2);
  std::vector<std::thread> fault_threads;
  if (o_.faults.malformed) {
    fault_threads.emplace_back([&] { Malformed(0, sessions[0], &stop_faults, &fault_results[0]); });
  }
  std::vector<client::CommandRecord> burst_records;
  if (o_.faults.burst) {
    fault_threads.emplace_back([&] {
      client::CommandChannel ch(Factory(&sessions[0]), RefOf(sessions[0]), "burst");
      for (int k = 0; k < o_.burst_commands; ++k) {
        Command c;
        *c.mutable_set_gravity() = V(0, 0, -9.81 * (k % 2));
        (void)ch.Send(c, "burst");
      }
      if (absl::Status s = ch.WaitAll(absl::Seconds(90)); !s.ok()) {
        fault_results[1].problems.push_back(absl::StrCat("burst: ", s.ToString()));
      }
      (void)ch.Close(absl::Seconds(10));
      burst_records = ch.Records();
    });
  }
  if (o_.faults.restart) {
    std::this_thread::sleep_until(start_ + std::chrono::duration<double>(o_.seconds * o_.restart_at));
    Log("SIGKILL to the server");
    server_->Kill();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    if (absl::Status s = server_->Start(); !s.ok()) {
      rep.problems.push_back(absl::StrCat("restart: ", s.ToString()));
    } else {
      ++restarts_;
      Log(absl::StrCat("restarted on ", server_->address()));
    }
  }
  // Where the CPU went: the threads' times just before the clients end
  // (a thread that has ended takes its run-queue time with it).
  std::this_thread::sleep_until(start_ + std::chrono::duration<double>(o_.seconds) -
                                std::chrono::milliseconds(100));
  const double cpu_seconds = std::chrono::duration<double>(Clock::now() - start_).count();
  const CpuSnapshot server_cpu1 = TakeCpuSnapshot(restarts_ > 0 ? 0 : server_pid);
  const CpuSnapshot tool_cpu1 = TakeCpuSnapshot(getpid());
  for (std::thread& t : threads) t.join();
  stop_faults = true;
  for (std::thread& t : fault_threads) t.join();
  const double run_seconds = std::chrono::duration<double>(Clock::now() - start_).count();
  const SessionStats after = stats(sessions[0]);
  sampling = false;
  if (sampler.joinable()) sampler.join();

  // Figures.
  std::vector<double> ack, visible, visible_no_build;
  std::map<std::string, std::vector<double>> visible_by_kind;
  double fps_sum = 0;
  for (int i = 0; i < o_.clients; ++i) {
    ClientResult& r = results[i];
    for (const std::string& p : r.problems) rep.problems.push_back(p);
    std::sort(r.frames.begin(), r.frames.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    for (const client::CommandRecord& rec : r.records) {
      ++rep.sent;
      rep.resends += rec.writes - 1;
      rep.rate_limited += rec.rate_limited;
      if (!rec.answered) continue;
      ++rep.codes[CodeName(rec.reply.code())];
      if (rec.reply.applied_step() < 0) continue;
      ++rep.acknowledged;
      (rec.reply.code() == 0 ? rep.applied : rep.rejected) += 1;
      const std::string kind = KindName(rec.command);
      if (rec.reply.code() != 0 && o_.verbose) {
        Log(absl::StrCat("refused ", kind, ": ", rec.reply.message()));
      }
      if (!rec.reply.duplicate()) {
        Report::Hold& h = rep.hold[kind];
        ++h.count;
        h.total_ms += rec.reply.hold_ms();
        h.max_ms = std::max(h.max_ms, rec.reply.hold_ms());
      }
      ack.push_back(rec.latency_ms);
      // Visible: the first frame at or after the applied step received
      // after the command was sent; for applied commands only (a refused
      // one changed nothing there is to see: its ack is its answer).
      if (rec.reply.code() != 0) continue;
      for (const auto& [step, at] : r.frames) {
        if (at >= rec.sent && step >= rec.reply.applied_step()) {
          const double ms = Ms(at - rec.sent);
          visible.push_back(ms);
          visible_by_kind[kind].push_back(ms);
          if (BuildsNothing(rec.command)) visible_no_build.push_back(ms);
          break;
        }
      }
    }
    rep.frames += r.watch.frames;
    rep.frames_skipped += r.watch.skipped;
    rep.reconnects += r.reconnects + r.watch.reconnects;
    if (r.watch.seconds > 0) fps_sum += (r.watch.frames - 1) / r.watch.seconds;
  }
  for (ClientResult& f : fault_results) {
    for (const std::string& p : f.problems) rep.problems.push_back(p);
    for (const auto& [k, v] : f.fault_codes) rep.codes[k] += v;
  }
  for (const client::CommandRecord& rec : burst_records) {
    rep.rate_limited += rec.rate_limited;
    if (rec.answered) ++rep.codes[absl::StrCat("burst: ", CodeName(rec.reply.code()))];
  }
  rep.frames_per_second = o_.clients > 0 ? fps_sum / o_.clients : 0;
  rep.commands_per_second = run_seconds > 0 ? rep.acknowledged / run_seconds : 0;
  rep.ack_ms = Summarize(ack);
  rep.visible_ms = Summarize(visible);
  rep.visible_no_build_ms = Summarize(visible_no_build);
  for (auto& [kind, v] : visible_by_kind) rep.visible_by_kind_ms[kind] = Summarize(v);
  rep.loaded_steps_per_second =
      run_seconds > 0 ? (after.step() - before.step()) / run_seconds : 0;
  rep.step_ms_median = after.step_ms_median();
  rep.step_ms_p99 = after.step_ms_p99();
  rep.steps_dropped = after.steps_dropped() - (restarts_ > 0 ? 0 : before.steps_dropped());
  rep.overruns = after.overruns() - (restarts_ > 0 ? 0 : before.overruns());
  rep.time_step = after.time_step();
  rep.restarts = restarts_;
  double cpu = 0;
  for (const auto& s : rep.server_samples) cpu += s[1];
  rep.server_cpu_percent = rep.server_samples.empty() ? 0 : cpu / rep.server_samples.size();
  if (!rep.server_samples.empty()) rep.server_rss_end_kb = static_cast<int64_t>(rep.server_samples.back()[2]);
  rep.busy_cores = BusyCoresBetween(tool_cpu0, tool_cpu1);
  rep.cores = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  for (const auto& [name, use] : CpuBetween(tool_cpu0, tool_cpu1, cpu_seconds)) {
    rep.load_tool.Add(use);
  }
  if (restarts_ == 0 && run_seconds > 0) {
    rep.build_busy_ms_per_s = (after.build_ms_total() - before.build_ms_total()) / run_seconds;
    rep.builds.cpu_ms_per_s = (after.build_cpu_ms_total() - before.build_cpu_ms_total()) / run_seconds;
    rep.builds.wait_ms_per_s =
        (after.build_wait_ms_total() - before.build_wait_ms_total()) / run_seconds;
    rep.builds.runs_per_s = (after.builds() - before.builds()) / run_seconds;
    rep.builds.threads = 1;
  }
  if (server_pid > 0 && restarts_ == 0) {
    for (const auto& [name, use] : CpuBetween(server_cpu0, server_cpu1, cpu_seconds)) {
      const bool own = name == "sim" || name == "encode" || name == "journal";
      rep.server_threads[own ? name : "gRPC and other"].Add(use);
    }
  }

  // Nothing lost: every client against the journal.
  if (server_ != nullptr || !o_.server.empty()) {
    std::vector<std::string> problems;
    for (int i = 0; i < o_.clients; ++i) {
      Verify(sessions[o_.shared ? 0 : i], absl::StrCat("load-", i), results[i].records, &problems);
    }
    if (o_.faults.burst) Verify(sessions[0], "burst", burst_records, &problems);
    rep.verified = true;
    for (const std::string& p : problems) rep.problems.push_back(p);
  }
  for (const Session& s : sessions) {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    google::protobuf::Empty e;
    (void)Sessions::NewStub(Factory(&s)())->CloseSession(&c, RefOf(s), &e);
  }
  if (server_ != nullptr) {
    const int code = server_->Stop();
    if (code != 0) rep.problems.push_back(absl::StrCat("the server exited ", code, " after SIGTERM"));
  }
  if (o_.max_rss_mb > 0 && rep.server_rss_max_kb > o_.max_rss_mb * 1024) {
    rep.problems.push_back(absl::StrCat("the server's resident memory reached ",
                                        rep.server_rss_max_kb / 1024, " MB (bound ", o_.max_rss_mb,
                                        " MB)"));
  }
  if (!temp_dir.empty()) std::system(absl::StrCat("rm -rf '", temp_dir, "'").c_str());
  rep.wall_seconds = std::chrono::duration<double>(Clock::now() - wall0).count();
  return rep;
}

}  // namespace

std::vector<std::string> CheckAgainstJournal(const std::string& client_id,
                                             const std::vector<client::CommandRecord>& records,
                                             const CommandLog& log) {
  std::vector<std::string> out;
  std::vector<std::string>* problems = &out;
  std::map<uint64_t, const client::CommandRecord*> by_seq;
  for (const client::CommandRecord& rec : records) by_seq[rec.seq] = &rec;
  std::map<uint64_t, int> seen;
  uint64_t last = 0;
  for (const CommandLogEntry& e : log.entries()) {
    auto it = by_seq.find(e.seq());
    const std::string what = absl::StrCat(client_id, " seq ", e.seq(), " (", e.kind(), ")");
    if (it == by_seq.end()) {
      problems->push_back(absl::StrCat(what, ": in the journal but never sent"));
      continue;
    }
    if (++seen[e.seq()] > 1) problems->push_back(absl::StrCat(what, ": applied twice"));
    if (e.seq() <= last) {
      problems->push_back(absl::StrCat(what, ": applied after seq ", last, " (out of order)"));
    }
    last = std::max(last, e.seq());
    const CommandReply& reply = it->second->reply;
    if (it->second->answered && reply.code() != e.code()) {
      problems->push_back(absl::StrCat(what, ": answered ", CodeName(reply.code()),
                                       ", journaled ", CodeName(e.code())));
    }
  }
  for (const client::CommandRecord& rec : records) {
    if (rec.answered && rec.reply.applied_step() < 0) {
      // Refused before it was considered, for good (a rate-limited answer
      // is resent by the channel and never ends here).
      problems->push_back(absl::StrCat(client_id, " seq ", rec.seq, ": never applied: ",
                                       CodeName(rec.reply.code()), ": ", rec.reply.message()));
    }
    if (!rec.answered || rec.reply.applied_step() < 0) continue;  // not acknowledged
    if (seen.count(rec.seq) == 0) {
      problems->push_back(absl::StrCat(client_id, " seq ", rec.seq, " (", KindName(rec.command),
                                       "): acknowledged at step ", rec.reply.applied_step(),
                                       " but not in the journal (lost)"));
    }
  }
  return out;
}

absl::StatusOr<Faults> ParseFaults(const std::string& list) {
  Faults f;
  if (list.empty() || list == "none") return f;
  for (absl::string_view name : absl::StrSplit(list, ',')) {
    if (name == "disconnect") {
      f.disconnect = true;
    } else if (name == "stop_reading") {
      f.stop_reading = true;
    } else if (name == "malformed") {
      f.malformed = true;
    } else if (name == "burst") {
      f.burst = true;
    } else if (name == "restart") {
      f.restart = true;
    } else if (name == "all") {
      f = Faults{true, true, true, true, true};
    } else {
      return absl::InvalidArgumentError(absl::StrCat(
          "--faults: unknown fault \"", name,
          "\" (disconnect, stop_reading, malformed, burst, restart, all, none)"));
    }
  }
  return f;
}

absl::StatusOr<Report> Run(const Options& options) {
  if (options.clients < 1 || options.clients > 1024) {
    return absl::InvalidArgumentError(absl::StrCat("--clients must be in [1, 1024], got ", options.clients));
  }
  if (!(options.seconds > 0) || options.seconds > 3600) {
    return absl::InvalidArgumentError(absl::StrCat("--seconds must be in (0, 3600], got ", options.seconds));
  }
  if (!(options.rate > 0) || options.rate > 1000) {
    return absl::InvalidArgumentError(absl::StrCat("--rate must be in (0, 1000] commands/s, got ", options.rate));
  }
  if (options.server.empty() == options.server_binary.empty()) {
    return absl::InvalidArgumentError("give exactly one of --server ADDR and --server_binary PATH");
  }
  LoadRun run(options);
  return run.Run();
}

std::string ReportJson(const Report& r) {
  auto pct = [](const Percentiles& p) {
    return absl::StrFormat("{\"count\": %d, \"p50\": %.3f, \"p99\": %.3f, \"p999\": %.3f, \"max\": %.3f}",
                           p.count, p.p50, p.p99, p.p999, p.max);
  };
  std::string codes;
  for (const auto& [k, v] : r.codes) absl::StrAppend(&codes, codes.empty() ? "" : ", ", "\"", k, "\": ", v);
  std::string placed;
  for (const auto& [k, v] : r.sessions_per_replica) {
    absl::StrAppend(&placed, placed.empty() ? "" : ", ", "\"", k, "\": ", v);
  }
  std::string hold;
  for (const auto& [k, h] : r.hold) {
    absl::StrAppend(&hold, hold.empty() ? "" : ", ",
                    absl::StrFormat("\"%s\": {\"count\": %d, \"total_ms\": %.1f, \"max_ms\": %.2f}",
                                    k, h.count, h.total_ms, h.max_ms));
  }
  std::string by_kind;
  for (const auto& [k, p] : r.visible_by_kind_ms) {
    absl::StrAppend(&by_kind, by_kind.empty() ? "" : ", ", "\"", k, "\": ", pct(p));
  }
  std::string samples;
  for (const auto& s : r.server_samples) {
    absl::StrAppend(&samples, samples.empty() ? "" : ", ", absl::StrFormat("[%.3f, %.1f, %.0f]", s[0], s[1], s[2]));
  }
  auto use = [](const CpuUse& u) {
    return absl::StrFormat(
        "{\"threads\": %d, \"cpu_ms_per_s\": %.1f, \"wait_ms_per_s\": %.1f, \"runs_per_s\": %.0f}",
        u.threads, u.cpu_ms_per_s, u.wait_ms_per_s, u.runs_per_s);
  };
  std::string threads;
  for (const auto& [name, u] : r.server_threads) {
    absl::StrAppend(&threads, threads.empty() ? "" : ", ", "\"", name, "\": ", use(u));
  }
  std::string problems;
  for (const std::string& p : r.problems) {
    std::string q = p;
    for (size_t k = 0; (k = q.find('"', k)) != std::string::npos; k += 2) q.replace(k, 1, "\\\"");
    absl::StrAppend(&problems, problems.empty() ? "" : ", ", "\"", q, "\"");
  }
  const Options& o = r.options;
  return absl::StrCat(
      "{\n  \"scene\": \"", o.scene, "\", \"clients\": ", o.clients, ", \"shared\": ",
      o.shared ? "true" : "false", ", \"seconds\": ", o.seconds, ", \"rate\": ", o.rate,
      ", \"seed\": ", o.seed, ", \"edits\": ", o.edits ? "true" : "false",
      ",\n  \"faults\": {\"disconnect\": ", o.faults.disconnect ? "true" : "false",
      ", \"stop_reading\": ", o.faults.stop_reading ? "true" : "false",
      ", \"malformed\": ", o.faults.malformed ? "true" : "false",
      ", \"burst\": ", o.faults.burst ? "true" : "false",
      ", \"restart\": ", o.faults.restart ? "true" : "false", "}",
      ",\n  \"sent\": ", r.sent, ", \"acknowledged\": ", r.acknowledged, ", \"applied\": ", r.applied,
      ", \"rejected\": ", r.rejected, ", \"commands_per_second\": ", absl::StrFormat("%.1f", r.commands_per_second),
      ",\n  \"ack_ms\": ", pct(r.ack_ms), ",\n  \"visible_ms\": ", pct(r.visible_ms),
      ",\n  \"visible_no_build_ms\": ", pct(r.visible_no_build_ms),
      ",\n  \"visible_by_kind_ms\": {", by_kind, "}",
      ",\n  \"codes\": {", codes, "}", ",\n  \"hold\": {", hold, "}",
      ",\n  \"frames\": ", r.frames, ", \"frames_skipped\": ", r.frames_skipped,
      ", \"frames_per_second\": ", absl::StrFormat("%.1f", r.frames_per_second),
      ", \"reconnects\": ", r.reconnects, ", \"resends\": ", r.resends, ", \"rate_limited\": ", r.rate_limited,
      ",\n  \"time_step\": ", r.time_step,
      ", \"unloaded_steps_per_second\": ", absl::StrFormat("%.1f", r.unloaded_steps_per_second),
      ", \"loaded_steps_per_second\": ", absl::StrFormat("%.1f", r.loaded_steps_per_second),
      ", \"step_ms_median\": ", absl::StrFormat("%.3f", r.step_ms_median),
      ", \"step_ms_p99\": ", absl::StrFormat("%.3f", r.step_ms_p99),
      ", \"steps_dropped\": ", r.steps_dropped, ", \"overruns\": ", r.overruns,
      ",\n  \"server_cpu_percent\": ", absl::StrFormat("%.1f", r.server_cpu_percent),
      ", \"server_rss_max_kb\": ", r.server_rss_max_kb, ", \"server_rss_end_kb\": ", r.server_rss_end_kb,
      ", \"restarts\": ", r.restarts, ", \"sessions_per_replica\": {", placed, "}",
      ",\n  \"server_samples\": [", samples, "]",
      ",\n  \"server_threads\": {", threads, "}, \"load_tool\": ", use(r.load_tool),
      ", \"busy_cores\": ", absl::StrFormat("%.2f", r.busy_cores), ", \"cores\": ", r.cores,
      ",\n  \"builds\": ", use(r.builds),
      ", \"build_busy_ms_per_s\": ", absl::StrFormat("%.1f", r.build_busy_ms_per_s),
      ",\n  \"verified\": ", r.verified ? "true" : "false", ", \"problems\": [", problems, "]",
      ",\n  \"wall_seconds\": ", absl::StrFormat("%.1f", r.wall_seconds), "\n}\n");
}

std::string ReportMarkdown(const Report& r) {
  const Options& o = r.options;
  std::string faults;
  for (const auto& [on, name] : {std::pair{o.faults.disconnect, "disconnect"},
                                 std::pair{o.faults.stop_reading, "stop_reading"},
                                 std::pair{o.faults.malformed, "malformed"},
                                 std::pair{o.faults.burst, "burst"},
                                 std::pair{o.faults.restart, "restart"}}) {
    if (on) absl::StrAppend(&faults, faults.empty() ? "" : ", ", name);
  }
  std::string out = absl::StrFormat(
      "| scene | clients | sessions | faults | commands/s | ack p50 / p99 / p99.9 / max (ms) | "
      "visible p50 / p99 / p99.9 / max (ms) | visible p50 / p99 of commands that build nothing "
      "(ms) | steps/s unloaded -> loaded (h = %g s) | step ms "
      "median / p99 | dropped | frames/s per watcher | skipped | server CPU %% / RSS max (MB) | "
      "lost, duplicated, reordered |\n"
      "| --- | ---: | --- | --- | ---: | --- | --- | --- | --- | --- | ---: | ---: | ---: | --- | "
      "--- |\n",
      r.time_step);
  absl::StrAppend(
      &out,
      absl::StrFormat("| %s | %d | %s | %s | %.1f | %.2f / %.2f / %.2f / %.2f | %.2f / %.2f / %.2f / "
                      "%.2f | %.2f / %.2f | %.0f -> %.0f | %.3f / %.3f | %d | %.1f | %d | %.0f / "
                      "%.0f | %s |\n",
                      o.scene, o.clients, o.shared ? "one shared" : "one each",
                      faults.empty() ? "none" : faults, r.commands_per_second, r.ack_ms.p50,
                      r.ack_ms.p99, r.ack_ms.p999, r.ack_ms.max, r.visible_ms.p50, r.visible_ms.p99,
                      r.visible_ms.p999, r.visible_ms.max, r.visible_no_build_ms.p50,
                      r.visible_no_build_ms.p99, r.unloaded_steps_per_second,
                      r.loaded_steps_per_second, r.step_ms_median, r.step_ms_p99, r.steps_dropped,
                      r.frames_per_second, r.frames_skipped, r.server_cpu_percent,
                      r.server_rss_max_kb / 1024.0,
                      !r.verified ? "not checked" : r.problems.empty() ? "none" : "**see problems**"));
  if (r.cores > 0) {
    // Where the CPU went: a second table, after a blank line.
    auto cell = [](const CpuUse& u) {
      const double mean_us = u.runs_per_s > 0 ? 1e3 * u.wait_ms_per_s / u.runs_per_s : 0;
      return absl::StrFormat("%.0f / %.0f, %.0f us (%d)", u.cpu_ms_per_s, u.wait_ms_per_s, mean_us,
                             u.threads);
    };
    std::string head = "| busy cores | dynsolid-load (clients) | server builds: busy / CPU / wait (builds/s) |",
                rule = "| ---: | --- | --- |";
    std::string row = absl::StrFormat("| %.2f of %d | %s | %.0f / %.0f / %.0f (%.1f) |", r.busy_cores,
                                      r.cores, cell(r.load_tool), r.build_busy_ms_per_s,
                                      r.builds.cpu_ms_per_s, r.builds.wait_ms_per_s,
                                      r.builds.runs_per_s);
    for (const auto& [name, u] : r.server_threads) {
      absl::StrAppend(&head, " server ", name, " |");
      absl::StrAppend(&rule, " --- |");
      absl::StrAppend(&row, " ", cell(u), " |");
    }
    absl::StrAppend(&out, "\nCPU per second of the run: ms on a CPU / ms ready but waiting for one, "
                          "the mean wait each time it was woken (threads):\n\n", head, "\n", rule,
                    "\n", row, "\n");
  }
  return out;
}

}  // namespace dynsolid::load
