// What a SessionLoop tells about itself: inspections of its solid
// (Inspect and Query, answered on the simulation thread at a step
// boundary) and its stats (the counters the simulation and persistence
// threads keep, and Stats, which reads them on a gRPC thread).
#include "server/session_loop.h"

#include <algorithm>
#include <chrono>
#include <deque>
#include <string>
#include <utility>
#include <vector>

#include "solver/common/stats.h"

namespace dynsolid::server {
namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kStepWindow = 1000;

void PushWindow(std::deque<double>& d, double v) {
  d.push_back(v);
  if (d.size() > kStepWindow) d.pop_front();
}

// The control mesh with the ids topology edits take.
void FillControlMesh(const scene::Discretization& d, ControlMeshInfo* out) {
  const mesh::CellComplex& c = d.control();
  const Points& p = c.positions();
  out->mutable_rest_positions()->Reserve(static_cast<int>(p.size()));
  for (int32_t v = 0; v < c.num_vertices(); ++v) {
    for (int a = 0; a < 3; ++a) out->add_rest_positions(p(v, a));
  }
  out->add_face_offsets(0);
  for (int32_t f = 0; f < c.num_faces(); ++f) {
    for (int32_t v : c.face_vertices(f)) out->add_face_vertices(v);
    out->add_face_offsets(out->face_vertices_size());
    out->add_face_cells(c.face_cells(f)[0]);
    out->add_face_cells(c.face_cells(f)[1]);
  }
  for (int32_t e = 0; e < c.num_edges(); ++e) {
    out->add_edge_vertices(c.edge_vertices(e)[0]);
    out->add_edge_vertices(c.edge_vertices(e)[1]);
    out->add_edge_sharp(static_cast<size_t>(e) < d.control_sharp.size() && d.control_sharp[e] != 0);
  }
  out->set_cells(c.num_cells());
}

}  // namespace

// ---- Inspections ----

void SessionLoop::Inspect(const InspectRequest& request,
                          std::function<void(absl::StatusOr<InspectReply>)> done,
                          std::function<bool()> cancelled) {
  {
    absl::MutexLock lock(&mu_);
    if (!stop_) {
      inspects_.push_back(PendingInspect{request, std::move(done), std::move(cancelled), nullptr});
      wake_.Signal();
      return;
    }
  }
  done(absl::UnavailableError("the session is closed"));
}

void SessionLoop::Query(std::function<void(const SimCore*)> fn) {
  {
    absl::MutexLock lock(&mu_);
    if (!stop_) {
      inspects_.push_back(PendingInspect{InspectRequest(), nullptr, nullptr, std::move(fn)});
      wake_.Signal();
      return;
    }
  }
  fn(nullptr);
}

void SessionLoop::AnswerInspects(bool all_unavailable) {
  if (waiting_inspects_.empty()) return;
  std::vector<PendingInspect> keep;
  for (PendingInspect& i : waiting_inspects_) {
    if (i.query != nullptr) {
      i.query(all_unavailable ? nullptr : core_.get());
      continue;
    }
    if (all_unavailable) {
      i.done(absl::UnavailableError("the session is closed"));
      continue;
    }
    if (i.request.wait_for_step() > core_->steps()) {
      if (i.cancelled != nullptr && i.cancelled()) {
        i.done(absl::CancelledError("the client cancelled the inspection"));
      } else {
        keep.push_back(std::move(i));
      }
      continue;
    }
    InspectReply r;
    const solid::Solid& s = core_->solid();
    r.set_step(s.steps());
    r.set_time(s.time());
    r.set_paused(core_->paused());
    r.set_steps_remaining(core_->steps_remaining());
    r.set_topology_version(s.topology_version());
    r.set_surface_vertices(static_cast<int32_t>(s.BoundarySurface().nodes.size()));
    if (i.request.surface_positions()) {
      const Points p = s.SurfacePositions();
      r.mutable_surface_positions()->Assign(p.data(), p.data() + p.size());
    }
    if (i.request.control_positions()) {
      const Points& p = s.control_positions();
      r.mutable_control_positions()->Assign(p.data(), p.data() + p.size());
    }
    if (i.request.control_mesh()) FillControlMesh(s.discretization(), r.mutable_control_mesh());
    if (i.request.loads()) core_->DescribeLoads(&r);
    if (i.request.history()) core_->DescribeHistory(r.mutable_history());
    i.done(std::move(r));
  }
  waiting_inspects_ = std::move(keep);
}

// ---- Stats ----

void SessionLoop::UpdateCounters() {
  absl::MutexLock lock(&stats_mu_);
  counters_.step = core_->steps();
  counters_.time = core_->solid().time();
  counters_.paused = core_->paused();
  counters_.steps_remaining = core_->steps_remaining();
  counters_.last_error = core_->last_error();
  counters_.rollbacks = core_->solid().rollbacks();
  counters_.fields_version = core_->fields_version();
  counters_.applied = core_->commands_applied();
  counters_.rejected = core_->commands_rejected();
  const UndoHistory& h = core_->history();
  counters_.undo_depth = h.undo_depth();
  counters_.redo_depth = h.redo_depth();
  counters_.history_bytes = h.bytes();
  counters_.history_limit = h.limit_bytes();
  counters_.topology_version = core_->solid().topology_version();
  counters_.hold_ms = core_->last_hold_ms();
  counters_.control_cells = core_->solid().discretization().control().num_cells();
  counters_.control_vertices = core_->solid().discretization().control().num_vertices();
}

void SessionLoop::RecordStep(double ms) {
  const solid::PhaseTimes& p = core_->solid().last_phases();
  const std::pair<const char*, double> phases[] = {
      {"nodes", p.nodes},         {"measure", p.measure}, {"stiffness", p.stiffness},
      {"project", p.project},     {"loads", p.loads},     {"damping", p.damping},
      {"solve", p.solve},         {"contact", contact_ms_}};
  absl::MutexLock lock(&stats_mu_);
  PushWindow(counters_.step_ms, ms);
  for (const auto& [name, value] : phases) {
    if (value < 0) continue;  // absent in this scene
    auto it = std::find_if(counters_.phases.begin(), counters_.phases.end(),
                           [n = name](const auto& e) { return e.first == n; });
    if (it == counters_.phases.end()) {
      counters_.phases.emplace_back(name, std::deque<double>());
      it = counters_.phases.end() - 1;
    }
    PushWindow(it->second, value);
  }
}

void SessionLoop::CountStepRate(Schedule& schedule, Clock::time_point now) {
  if (now - schedule.rate_start >= std::chrono::seconds(1)) {
    absl::MutexLock lock(&stats_mu_);
    counters_.steps_per_second =
        schedule.rate_steps / std::chrono::duration<double>(now - schedule.rate_start).count();
    schedule.rate_start = now;
    schedule.rate_steps = 0;
  }
}

SessionStats SessionLoop::Stats() const {
  SessionStats s;
  std::vector<WatcherStats> watchers;
  {
    absl::MutexLock lock(&mu_);
    for (const auto& [ptr, entry] : watchers_) {
      WatcherStats w = entry.sink->Stats();
      w.set_watcher_id(entry.id);
      watchers.push_back(std::move(w));
    }
  }
  std::sort(watchers.begin(), watchers.end(),
            [](const WatcherStats& a, const WatcherStats& b) {
              return a.watcher_id() < b.watcher_id();
            });
  absl::MutexLock lock(&stats_mu_);
  const Counters& c = counters_;
  s.set_step(c.step);
  s.set_time(c.time);
  s.set_paused(c.paused);
  s.set_steps_remaining(c.steps_remaining);
  s.set_time_step(time_step_);
  std::vector<double> ms(c.step_ms.begin(), c.step_ms.end());
  s.set_step_ms_median(Percentile(ms, 0.5));
  s.set_step_ms_p99(Percentile(ms, 0.99));
  s.set_steps_measured(static_cast<int64_t>(ms.size()));
  for (const auto& [name, values] : c.phases) {
    PhaseTime* p = s.add_phases();
    p->set_name(name);
    p->set_median_ms(Percentile(std::vector<double>(values.begin(), values.end()), 0.5));
  }
  s.set_steps_behind(c.steps_behind);
  s.set_overruns(c.overruns);
  s.set_steps_dropped(c.steps_dropped);
  s.set_steps_per_second(c.steps_per_second);
  s.set_watchers(static_cast<int32_t>(watchers.size()));
  int64_t sent = c.gone_sent, skipped = c.gone_skipped, keys = c.gone_keyframes,
          bytes = c.gone_bytes;
  for (WatcherStats& w : watchers) {
    sent += w.frames_sent();
    skipped += w.frames_skipped();
    keys += w.keyframes_sent();
    bytes += w.bytes_sent();
    *s.add_watcher_details() = std::move(w);
  }
  s.set_frames_published(c.frames_published);
  s.set_frames_sent(sent);
  s.set_frames_skipped(skipped);
  s.set_keyframes_sent(keys);
  s.set_bytes_sent(bytes);
  s.set_commands_applied(c.applied);
  s.set_commands_rejected(c.rejected);
  s.set_commands_duplicate(c.duplicates);
  s.set_commands_rate_limited(rate_limited_.load());
  s.set_journal_records(c.journal_records);
  s.set_journal_bytes(c.journal_bytes);
  s.set_snapshots(c.snapshots);
  s.set_last_snapshot_step(c.last_snapshot_step);
  s.set_rollbacks(c.rollbacks);
  s.set_last_error(c.last_error);
  s.set_fields_version(c.fields_version);
  s.set_undo_depth(c.undo_depth);
  s.set_redo_depth(c.redo_depth);
  s.set_history_bytes(c.history_bytes);
  s.set_history_limit_bytes(c.history_limit);
  s.set_topology_version(c.topology_version);
  s.set_last_command_hold_ms(c.hold_ms);
  s.set_control_cells(c.control_cells);
  s.set_control_vertices(c.control_vertices);
  s.set_builds(c.builds);
  s.set_build_ms_total(c.build_ms);
  s.set_build_cpu_ms_total(c.build_cpu_ms);
  s.set_build_wait_ms_total(c.build_wait_ms);
  probes_.FillStats(&s);
  return s;
}

}  // namespace dynsolid::server
