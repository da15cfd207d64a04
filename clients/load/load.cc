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
#include "absl/strings/str_split.h"
#include "clients/lib/channel.h"
#include "clients/lib/command_channel.h"
#include "clients/lib/watcher.h"
#include "clients/load/mix.h"
#include "clients/load/report.h"
#include "clients/load/server_process.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::load {
namespace {

using Clock = std::chrono::steady_clock;
using client::ChannelFactory;

// The client's own loads and drags (by the seq that made them).
struct Owned {
  std::vector<uint64_t> loads, drags, fixes;
  std::vector<std::pair<uint64_t, int>> curves;  // seq, points
};

// The threads beside the clients that inject faults, and what they found
// (results[0]: malformed traffic, results[1]: the burst).
struct FaultRun {
  std::atomic<bool> stop{false};
  std::vector<ClientResult> results = std::vector<ClientResult>(2);
  std::vector<client::CommandRecord> burst_records;
  std::vector<std::thread> threads;
};

class LoadRun {
 public:
  explicit LoadRun(const Options& o) : o_(o) {}

  // Starts (or finds) the server, opens the sessions, measures the unloaded
  // step rate, runs the clients and the faults, then collects the figures,
  // checks the journals and stops everything.
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
  // The TLS roots, and the server: one started here (with a temporary data
  // directory unless one is given) or the address given.
  absl::Status Connect();
  // The sessions (one shared, or one per client) and the box and material
  // points the commands aim at, from the first.
  absl::Status OpenSessions(Report& rep);
  absl::StatusOr<Session> CreateSession();
  SessionStats Stats(const Session& s) const;
  std::thread StartSampler(std::atomic<bool>* sampling, Report* rep);
  std::vector<std::thread> StartClients(std::vector<ClientResult>* results);
  void StartFaults(FaultRun* f);
  void Burst(FaultRun* f);
  // The restart fault: SIGKILL at `restart_at` of the run, then the server
  // started again on its data directory and port.
  void KillAndRestart(Report& rep);
  void VerifyJournals(const std::vector<ClientResult>& results, const FaultRun& faults, Report& rep);
  // Closes the sessions, stops a server started here (a clean exit is
  // expected), checks its resident maximum and removes the temporary data.
  void Finish(Report& rep);
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
  std::string temp_dir_;  // a data directory this tool made (removed at the end)
  std::vector<Session> sessions_;
  Box box_;
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

absl::Status LoadRun::Connect() {
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
      dir = temp_dir_ = tmpl;
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
  return absl::OkStatus();
}

absl::Status LoadRun::OpenSessions(Report& rep) {
  // Sessions: one shared, or one per client.
  for (int k = 0; k < (o_.shared ? 1 : o_.clients); ++k) {
    absl::StatusOr<Session> s = CreateSession();
    if (!s.ok()) return s.status();
    sessions_.push_back(*s);
  }
  for (const Session& s : sessions_) ++rep.sessions_per_replica[s.replica()];
  absl::StatusOr<Box> box = RestBox(*Sessions::NewStub(Factory(&sessions_[0])()), RefOf(sessions_[0]));
  if (!box.ok()) return box.status();
  box_ = *std::move(box);
  box_.inside = MaterialPoints(*Sessions::NewStub(Factory(&sessions_[0])()), RefOf(sessions_[0]),
                               box_, 256, o_.seed);
  Log(absl::StrCat(box_.inside.size(), " material points inside the solid for the commands"));
  return absl::OkStatus();
}

SessionStats LoadRun::Stats(const Session& s) const {
  SessionStats st;
  auto stub = Sessions::NewStub(Factory(&s)());
  (void)Retrying([&] {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return stub->GetStats(&c, RefOf(s), &st);
  });
  return st;
}

// CPU and memory of a server started here, every quarter second until
// `sampling` goes false. Only this thread touches the report's samples and
// resident maximum until it is joined.
std::thread LoadRun::StartSampler(std::atomic<bool>* sampling, Report* rep) {
  if (server_ == nullptr) return std::thread();
  return std::thread([this, sampling, rep] {
    double last_cpu = -1;
    auto last_t = Clock::now();
    while (sampling->load()) {
      double cpu = 0;
      long rss = 0;
      const auto now = Clock::now();
      if (server_->Sample(&cpu, &rss)) {
        const double dt = std::chrono::duration<double>(now - last_t).count();
        const double pct = last_cpu >= 0 && dt > 0 && cpu >= last_cpu ? 100 * (cpu - last_cpu) / dt : 0;
        if (last_cpu >= 0) {
          rep->server_samples.push_back({std::chrono::duration<double>(now - start_).count(), pct,
                                         static_cast<double>(rss)});
        }
        last_cpu = cpu;
        last_t = now;
        rep->server_rss_max_kb = std::max<int64_t>(rep->server_rss_max_kb, rss);
      } else {
        last_cpu = -1;  // restarting
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
    }
  });
}

std::vector<std::thread> LoadRun::StartClients(std::vector<ClientResult>* results) {
  std::vector<std::thread> threads;
  for (int i = 0; i < o_.clients; ++i) {
    threads.emplace_back([this, i, results] {
      Client(i, sessions_[o_.shared ? 0 : i], box_, &(*results)[i]);
    });
  }
  return threads;
}

void LoadRun::StartFaults(FaultRun* f) {
  if (o_.faults.malformed) {
    f->threads.emplace_back([this, f] { Malformed(0, sessions_[0], &f->stop, &f->results[0]); });
  }
  if (o_.faults.burst) f->threads.emplace_back([this, f] { Burst(f); });
}

// The burst fault: one client sending all its commands at once, above the
// server's rate limit (the channel resends what is rate limited).
void LoadRun::Burst(FaultRun* f) {
  client::CommandChannel ch(Factory(&sessions_[0]), RefOf(sessions_[0]), "burst");
  for (int k = 0; k < o_.burst_commands; ++k) {
    Command c;
    *c.mutable_set_gravity() = V(0, 0, -9.81 * (k % 2));
    (void)ch.Send(c, "burst");
  }
  if (absl::Status s = ch.WaitAll(absl::Seconds(90)); !s.ok()) {
    f->results[1].problems.push_back(absl::StrCat("burst: ", s.ToString()));
  }
  (void)ch.Close(absl::Seconds(10));
  f->burst_records = ch.Records();
}

void LoadRun::KillAndRestart(Report& rep) {
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

void LoadRun::VerifyJournals(const std::vector<ClientResult>& results, const FaultRun& faults,
                             Report& rep) {
  // Nothing lost: every client against the journal.
  if (server_ != nullptr || !o_.server.empty()) {
    std::vector<std::string> problems;
    for (int i = 0; i < o_.clients; ++i) {
      Verify(sessions_[o_.shared ? 0 : i], absl::StrCat("load-", i), results[i].records, &problems);
    }
    if (o_.faults.burst) Verify(sessions_[0], "burst", faults.burst_records, &problems);
    rep.verified = true;
    for (const std::string& p : problems) rep.problems.push_back(p);
  }
}

void LoadRun::Finish(Report& rep) {
  for (const Session& s : sessions_) {
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
  if (!temp_dir_.empty()) std::system(absl::StrCat("rm -rf '", temp_dir_, "'").c_str());
}

absl::StatusOr<Report> LoadRun::Run() {
  Report rep;
  rep.options = o_;
  const auto wall0 = Clock::now();
  if (absl::Status s = Connect(); !s.ok()) return s;
  if (absl::Status s = OpenSessions(rep); !s.ok()) return s;
  // The unloaded step rate: a second and a half with nobody connected.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  rep.unloaded_steps_per_second = Stats(sessions_[0]).steps_per_second();
  const SessionStats before = Stats(sessions_[0]);

  std::atomic<bool> sampling{true};
  start_ = Clock::now();
  std::thread sampler = StartSampler(&sampling, &rep);
  CpuWindow cpu;
  cpu.server_pid = server_ != nullptr ? server_->pid() : 0;
  cpu.server0 = TakeCpuSnapshot(cpu.server_pid);
  cpu.tool0 = TakeCpuSnapshot(getpid());

  std::vector<ClientResult> results(o_.clients);
  std::vector<std::thread> threads = StartClients(&results);
  // Faults beside the clients.
  FaultRun faults;
  StartFaults(&faults);
  if (o_.faults.restart) KillAndRestart(rep);
  // Where the CPU went: the threads' times just before the clients end
  // (a thread that has ended takes its run-queue time with it).
  std::this_thread::sleep_until(start_ + std::chrono::duration<double>(o_.seconds) -
                                std::chrono::milliseconds(100));
  cpu.seconds = std::chrono::duration<double>(Clock::now() - start_).count();
  cpu.server1 = TakeCpuSnapshot(restarts_ > 0 ? 0 : cpu.server_pid);
  cpu.tool1 = TakeCpuSnapshot(getpid());
  for (std::thread& t : threads) t.join();
  faults.stop = true;
  for (std::thread& t : faults.threads) t.join();
  const double run_seconds = std::chrono::duration<double>(Clock::now() - start_).count();
  const SessionStats after = Stats(sessions_[0]);
  sampling = false;
  if (sampler.joinable()) sampler.join();

  ClientFigures(o_, results, faults.results, faults.burst_records, run_seconds, rep);
  ServerFigures(before, after, cpu, restarts_, run_seconds, rep);
  VerifyJournals(results, faults, rep);
  Finish(rep);
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


}  // namespace dynsolid::load
