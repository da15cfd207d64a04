#include "server/session_loop.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "absl/time/time.h"
#include "dynsolid/journal.pb.h"
#include "server/log.h"
#include "server/thread_priority.h"

namespace dynsolid::server {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

absl::StatusOr<std::unique_ptr<SessionLoop>> SessionLoop::Start(std::string session_id,
                                                                std::unique_ptr<SimCore> core,
                                                                LoopOptions options,
                                                                std::string dir,
                                                                Recovered recovered) {
  std::unique_ptr<SessionLoop> loop(new SessionLoop(std::move(session_id), std::move(core),
                                                    std::move(options), std::move(dir),
                                                    recovered));
  if (!loop->dir_.empty()) {
    absl::StatusOr<std::unique_ptr<JournalWriter>> journal =
        JournalWriter::Open(absl::StrCat(loop->dir_, "/journal"), recovered.journal_end);
    if (!journal.ok()) return journal.status();
    loop->journal_ = *std::move(journal);
    loop->persist_thread_ = std::thread([l = loop.get()] { l->Persist(); });
  }
  loop->sim_thread_ = std::thread([l = loop.get()] { l->Run(); });
  return loop;
}

SessionLoop::SessionLoop(std::string session_id, std::unique_ptr<SimCore> core,
                         LoopOptions options, std::string dir, Recovered recovered)
    : id_(std::move(session_id)),
      options_(std::move(options)),
      dir_(std::move(dir)),
      time_step_(core->solid().time_step()),
      core_(std::move(core)) {
  journal_submitted_ = recovered.journal_end;
  last_snapshot_step_ = recovered.last_snapshot_step;
  absl::MutexLock lock(&stats_mu_);
  counters_.journal_records = recovered.journal_records;
  counters_.journal_bytes = static_cast<int64_t>(recovered.journal_end);
  counters_.last_snapshot_step = std::max<int64_t>(0, recovered.last_snapshot_step);
  counters_.step = core_->steps();
  counters_.time = core_->solid().time();
  counters_.paused = core_->paused();
  counters_.steps_remaining = core_->steps_remaining();
  counters_.applied = core_->commands_applied();
  counters_.rejected = core_->commands_rejected();
  counters_.fields_version = core_->fields_version();
  counters_.last_error = core_->last_error();
  probes_.set_wake([this] {
    absl::MutexLock lock(&mu_);
    wake_.Signal();
  });
}

SessionLoop::~SessionLoop() { Stop(absl::UnavailableError("the session is closed")); }

void SessionLoop::Stop(const absl::Status& status) {
  {
    absl::MutexLock lock(&mu_);
    if (stop_) {
      mu_.Await(absl::Condition(&stopped_));
      return;
    }
    stop_ = true;
    stop_status_ = status;
    wake_.SignalAll();
  }
  if (sim_thread_.joinable()) sim_thread_.join();
  if (persist_thread_.joinable()) {
    {
      absl::MutexLock lock(&persist_mu_);
      persist_stop_ = true;
    }
    persist_thread_.join();
  }
  journal_.reset();
  std::vector<std::shared_ptr<WatchSink>> watchers;
  std::vector<std::shared_ptr<ReplySink>> streams;
  std::deque<PendingCommand> unanswered;
  {
    absl::MutexLock lock(&mu_);
    for (auto& [ptr, entry] : watchers_) watchers.push_back(entry.sink);
    for (auto& [ptr, sink] : command_streams_) streams.push_back(sink);
    unanswered.swap(commands_);
  }
  for (auto& w : watchers) w->Stop(status);
  for (auto& s : streams) s->Stop(status);
  probes_.StopAll(status);
  for (PendingCommand& c : unanswered) c.sink->Stop(status);
  absl::MutexLock lock(&mu_);
  stopped_ = true;
}

bool SessionLoop::AllowCommand(const std::string& client_id, uint64_t seq) {
  const Clock::time_point now = Clock::now();
  const double rate = options_.commands_per_second;
  absl::MutexLock lock(&mu_);
  auto [it, inserted] = buckets_.try_emplace(client_id);
  Bucket& b = it->second;
  if (inserted) {
    b.tokens = rate;
  } else {
    const double dt = std::chrono::duration<double>(now - b.last).count();
    b.tokens = std::min(rate, b.tokens + dt * rate);
  }
  b.last = now;
  // Behind a refused seq: wait for it (its resend comes first).
  if (b.refused_from != 0 && seq > b.refused_from) return false;
  if (b.tokens < 1.0) {
    b.refused_from = b.refused_from == 0 ? seq : std::min(b.refused_from, seq);
    return false;
  }
  if (seq == b.refused_from) b.refused_from = 0;
  b.tokens -= 1.0;
  return true;
}

void SessionLoop::Submit(const CommandRequest& request, std::shared_ptr<ReplySink> sink) {
  absl::Status stopped;
  {
    absl::MutexLock lock(&mu_);
    if (!stop_) {
      commands_.push_back(PendingCommand{request, std::move(sink)});
      wake_.Signal();
      return;
    }
    stopped = stop_status_;
  }
  sink->Stop(stopped);  // no lock held: a reactor may finish inline
}

absl::Status SessionLoop::RegisterCommandStream(std::shared_ptr<ReplySink> sink) {
  absl::MutexLock lock(&mu_);
  if (stop_) return stop_status_;
  ReplySink* key = sink.get();
  command_streams_.emplace(key, std::move(sink));
  return absl::OkStatus();
}

void SessionLoop::UnregisterCommandStream(ReplySink* sink) {
  std::shared_ptr<ReplySink> gone;  // released after the lock
  absl::MutexLock lock(&mu_);
  auto it = command_streams_.find(sink);
  if (it == command_streams_.end()) return;
  gone = std::move(it->second);
  command_streams_.erase(it);
  // Its drags go with it (on the simulation thread, as commands).
  ended_streams_.push_back(sink);
  wake_.Signal();
}

void SessionLoop::ReleaseDragsOf(std::deque<PendingCommand>& commands) {
  if (streams_to_release_.empty()) return;
  std::vector<int64_t> ids;
  for (auto it = drag_owner_.begin(); it != drag_owner_.end();) {
    if (std::find(streams_to_release_.begin(), streams_to_release_.end(), it->second) !=
        streams_to_release_.end()) {
      ids.push_back(it->first);
      drag_owner_.erase(it++);
    } else {
      ++it;
    }
  }
  streams_to_release_.clear();
  std::sort(ids.begin(), ids.end());
  const std::vector<int64_t> live = core_->solid().load_ids();
  std::deque<PendingCommand> releases;
  for (int64_t id : ids) {
    if (!std::binary_search(live.begin(), live.end(), id)) continue;  // released already
    PendingCommand c;
    c.request.set_client_id(kReleaseClient);  // seq: given when applied
    c.request.mutable_command()->mutable_remove_load()->set_load_id(id);
    releases.push_back(std::move(c));
  }
  // Before what arrived since (the stream ended before those were read).
  for (auto it = releases.rbegin(); it != releases.rend(); ++it) {
    commands.push_front(std::move(*it));
  }
}

absl::StatusOr<int64_t> SessionLoop::AddWatcher(std::shared_ptr<WatchSink> sink) {
  absl::MutexLock lock(&mu_);
  if (stop_) return stop_status_;
  if (static_cast<int>(watchers_.size()) >= options_.max_watchers) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "session ", id_, " already has its maximum of ", options_.max_watchers,
        " watchers (--max_watchers_per_session)"));
  }
  const int64_t id = next_watcher_id_++;
  sink->set_watcher_id(id);
  WatchSink* key = sink.get();
  watchers_.emplace(key, WatcherEntry{std::move(sink), id});
  publish_requested_ = true;  // its first frame now, not at the next tick
  wake_.Signal();
  return id;
}

void SessionLoop::RemoveWatcher(WatchSink* sink) {
  std::shared_ptr<WatchSink> gone;
  {
    absl::MutexLock lock(&mu_);
    auto it = watchers_.find(sink);
    if (it == watchers_.end()) return;
    gone = std::move(it->second.sink);
    watchers_.erase(it);
  }
  const WatcherStats w = gone->Stats();
  absl::MutexLock lock(&stats_mu_);
  counters_.gone_sent += w.frames_sent();
  counters_.gone_skipped += w.frames_skipped();
  counters_.gone_keyframes += w.keyframes_sent();
  counters_.gone_bytes += w.bytes_sent();
}

// ---- Simulation thread ----

void SessionLoop::Run() {
  NameThisThread("sim");
  Schedule schedule;
  schedule.h =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(time_step_));
  // The most real-time debt the loop catches up rather than drops (a step,
  // if that is longer).
  schedule.catch_up = std::max<Clock::duration>(
      schedule.h, std::chrono::duration_cast<Clock::duration>(kCatchUp));
  schedule.rate_start = Clock::now();
  next_publish_ = Clock::now();
  for (;;) {
    Wakeup wakeup = WaitForWork(schedule);
    if (wakeup.stop) {
      RequeueUnapplied(wakeup.commands);
      break;
    }
    std::shared_ptr<SimCore::Prebuilt> finished = OrderCommands(wakeup.commands);
    ApplyCommands(wakeup.commands, std::move(finished));
    AnswerInspects(false);

    Clock::time_point now = Clock::now();
    if (core_->WantsStep()) {
      now = StepIfDue(schedule, now);
    } else {
      schedule.anchored = false;
      if (probes_.busy() && now >= schedule.next_probe_refresh) {
        UpdateProbes();
        schedule.next_probe_refresh =
            now + std::min<Clock::duration>(schedule.h, std::chrono::milliseconds(2));
      }
    }
    CountStepRate(schedule, now);
    if (wakeup.has_watchers) PublishIfDue(now, wakeup.publish_requested);
  }
  // Shutdown: a last snapshot makes the next start quick.
  if (!dir_.empty() && core_->steps() != last_snapshot_step_) {
    PersistBatch batch;
    batch.snapshot = MakeSnapshotBytes();
    batch.snapshot_step = core_->steps();
    Deliver(std::move(batch));
  }
  AnswerInspects(true);
}

SessionLoop::Wakeup SessionLoop::WaitForWork(const Schedule& schedule) {
  Wakeup wakeup;
  absl::MutexLock lock(&mu_);
  for (;;) {
    if (stop_ || !commands_.empty() || !inspects_.empty() || build_done_ ||
        !ended_streams_.empty()) {
      break;
    }
    const Clock::time_point now = Clock::now();
    Clock::time_point deadline = Clock::time_point::max();
    if (core_->WantsStep()) {
      deadline = schedule.anchored ? schedule.next_step : now;
    } else if (probes_.busy()) {
      deadline = schedule.next_probe_refresh;
    }
    const bool dirty = publish_requested_ || core_->steps() != last_published_step_ ||
                       core_->fields_version() != last_published_fields_;
    if (!watchers_.empty() && dirty) deadline = std::min(deadline, next_publish_);
    if (deadline <= now) break;
    const absl::Duration wait = deadline == Clock::time_point::max()
                                    ? absl::Seconds(1)
                                    : absl::FromChrono(deadline - now);
    wake_.WaitWithTimeout(&mu_, wait);
  }
  wakeup.stop = stop_;
  wakeup.commands.swap(commands_);
  for (ReplySink* ended : ended_streams_) streams_to_release_.push_back(ended);
  ended_streams_.clear();
  for (PendingInspect& i : inspects_) waiting_inspects_.push_back(std::move(i));
  inspects_.clear();
  wakeup.publish_requested = publish_requested_;
  wakeup.has_watchers = !watchers_.empty();
  return wakeup;
}

void SessionLoop::RequeueUnapplied(std::deque<PendingCommand>& commands) {
  // Commands not yet applied are not answered (the client resends): a
  // build under way is waited for and dropped.
  std::deque<PendingCommand> unapplied;
  if (building_.has_value()) {
    builder_.join();
    unapplied.push_back(*std::move(building_));
    building_.reset();
  }
  for (PendingCommand& c : held_) unapplied.push_back(std::move(c));
  held_.clear();
  held_clients_.clear();
  for (PendingCommand& c : commands) unapplied.push_back(std::move(c));
  absl::MutexLock lock(&mu_);
  built_.reset();
  build_done_ = false;
  for (PendingCommand& c : commands_) unapplied.push_back(std::move(c));
  commands_.swap(unapplied);
}

std::shared_ptr<SimCore::Prebuilt> SessionLoop::OrderCommands(
    std::deque<PendingCommand>& commands) {
  std::shared_ptr<SimCore::Prebuilt> finished;
  {
    absl::MutexLock lock(&mu_);
    if (build_done_) {
      finished = std::move(built_);
      build_done_ = false;
    }
  }
  if (finished != nullptr) {
    // The build is done: its command first, then the ones held behind it.
    builder_.join();
    std::deque<PendingCommand> next;
    next.push_back(*std::move(building_));
    building_.reset();
    for (PendingCommand& c : held_) next.push_back(std::move(c));
    held_.clear();
    held_clients_.clear();
    for (PendingCommand& c : commands) next.push_back(std::move(c));
    commands.swap(next);
  } else if (building_.has_value()) {
    HoldBehindBuild(commands);
  }
  // Releases wait for a build (the drags it holds back are not acting yet).
  if (!building_.has_value() || finished != nullptr) ReleaseDragsOf(commands);
  return finished;
}

Clock::time_point SessionLoop::StepIfDue(Schedule& schedule, Clock::time_point now) {
  if (!schedule.anchored) {
    schedule.next_step = now;  // resuming: no debt from the paused time
    schedule.anchored = true;
  }
  if (now < schedule.next_step) return now;
  UpdateProbes();  // before the step: its loads act during it
  const Clock::time_point t0 = Clock::now();
  if (absl::Status s = core_->StepOnce(); !s.ok()) {
    SessionLog().warn("session {}: {}; paused", id_, core_->last_error());
  }
  const Clock::time_point t1 = Clock::now();
  RecordStep(std::chrono::duration<double, std::milli>(t1 - t0).count());
  UpdateCounters();
  ++schedule.rate_steps;
  schedule.next_step += schedule.h;
  const Clock::duration lag = t1 - schedule.next_step;
  int64_t behind = 0;
  int64_t dropped = 0;
  bool overrun = false;
  if (lag > Clock::duration::zero()) behind = lag / schedule.h;
  if (lag > schedule.catch_up) {
    // Further behind than it may catch up: give the debt up and
    // re-anchor. Below that, the next steps run back to back until
    // the loop is on time again (a first step that warms its caches,
    // an edit installed, a moment without the CPU cost no step).
    overrun = true;
    dropped = behind;
    schedule.next_step = t1;
  }
  {
    absl::MutexLock lock(&stats_mu_);
    counters_.steps_behind = behind;
    counters_.steps_dropped += dropped;
    if (overrun) ++counters_.overruns;
  }
  AnswerInspects(false);
  if (!dir_.empty() && options_.snapshot_every_steps > 0 &&
      core_->steps() - std::max<int64_t>(last_snapshot_step_, 0) >=
          options_.snapshot_every_steps) {
    PersistBatch batch;
    batch.snapshot = MakeSnapshotBytes();
    batch.snapshot_step = core_->steps();
    Deliver(std::move(batch));
  }
  return Clock::now();
}

void SessionLoop::PublishIfDue(Clock::time_point now, bool publish_requested) {
  // Every watcher at the rate asked for; the commanding clients' after
  // the next step (frame_for_command_).
  const bool dirty = publish_requested || core_->steps() != last_published_step_ ||
                     core_->fields_version() != last_published_fields_;
  const bool early_dirty = core_->steps() != last_early_step_ ||
                           core_->fields_version() != last_early_fields_;
  if (dirty && (publish_requested || now >= next_publish_)) {
    Publish(now, /*early=*/false);
  } else if (frame_for_command_ && early_dirty && now >= earliest_publish_) {
    Publish(now, /*early=*/true);
  }
}

void SessionLoop::ApplyCommands(std::deque<PendingCommand>& commands,
                                std::shared_ptr<SimCore::Prebuilt> prebuilt) {
  if (commands.empty()) return;
  PersistBatch batch;
  int64_t duplicates = 0;
  // Journal first: a command whose record could not be written is not
  // applied. Its record's space is reserved before it is applied; when the
  // disk is full it, and every command after it in this batch (a client's
  // order is kept), is refused untouched.
  absl::Status no_room;
  for (size_t k = 0; k < commands.size(); ++k) {
    if (journal_ != nullptr && no_room.ok()) {
      no_room = journal_->Reserve(
          journal_submitted_ + commands[k].request.ByteSizeLong() + kJournalSlack,
          kJournalReserveStep);
      if (!no_room.ok() && options_.disk != nullptr) options_.disk->ReportFull(no_room.message());
    }
    if (!no_room.ok()) {
      PendingCommand& c = commands[k];
      CommandReply reply;
      reply.set_client_id(c.request.client_id());
      reply.set_seq(c.request.seq());
      reply.set_code(static_cast<int32_t>(absl::StatusCode::kResourceExhausted));
      absl::string_view why = no_room.message();
      absl::ConsumePrefix(&why, "no space left on the data disk: ");
      reply.set_message(absl::StrCat(
          "no space left on the data disk: the command was not applied, and nothing it would "
          "have done happened; send it again when there is room (",
          why, ")"));
      reply.set_applied_step(-1);
      SessionLog().warn("session {}: client {} seq {} refused: {}", id_, c.request.client_id(),
                        c.request.seq(), std::string(no_room.message()));
      prebuilt = nullptr;  // a finished build for it is dropped
      batch.replies.emplace_back(std::move(c.sink), std::move(reply));
      continue;
    }
    if (prebuilt == nullptr && core_->NeedsBuild(commands[k].request)) {
      // Build off the loop; this command waits for it, and so do the rest
      // but those HoldBehindBuild lets go ahead. What the server fills in
      // (a bake's positions) is taken now, and journaled with it.
      core_->Stamp(commands[k].request);
      std::function<std::shared_ptr<SimCore::Prebuilt>()> job =
          core_->Prebuild(commands[k].request);
      building_ = std::move(commands[k]);
      held_clients_.insert(building_->request.client_id());
      std::deque<PendingCommand> rest;
      for (size_t r = k + 1; r < commands.size(); ++r) rest.push_back(std::move(commands[r]));
      commands.resize(k);
      builder_ = std::thread([this, job = std::move(job)]() {
        NameThisThread("build");
        (void)LowerThisThreadPriority(options_.build_nice);
        const auto start = std::chrono::steady_clock::now();
        const ThreadCpu cpu0 = ThisThreadCpu();
        std::shared_ptr<SimCore::Prebuilt> result = job();
        const ThreadCpu cpu1 = ThisThreadCpu();
        {
          absl::MutexLock stats(&stats_mu_);
          ++counters_.builds;
          counters_.build_ms += std::chrono::duration<double, std::milli>(
                                    std::chrono::steady_clock::now() - start).count();
          counters_.build_cpu_ms += cpu1.cpu_ms - cpu0.cpu_ms;
          counters_.build_wait_ms += cpu1.wait_ms - cpu0.wait_ms;
        }
        absl::MutexLock lock(&mu_);
        built_ = std::move(result);
        build_done_ = true;
        wake_.Signal();
      });
      // Those behind it that may go ahead of the build are applied now,
      // after the ones before it.
      HoldBehindBuild(rest);
      for (PendingCommand& p : rest) commands.push_back(std::move(p));
      if (k == commands.size()) break;
    }
    PendingCommand& c = commands[k];
    if (c.request.seq() == 0 && c.request.client_id() == kReleaseClient) {
      c.request.set_seq(core_->LastSeq(kReleaseClient) + 1);
    }
    CommandReply reply;
    const SimCore::Outcome outcome = core_->Process(c.request, &reply, std::move(prebuilt));
    prebuilt = nullptr;
    const Command::KindCase kind = c.request.command().kind_case();
    if (outcome == SimCore::Outcome::kApplied && c.sink != nullptr &&
        (kind == Command::kDrag || kind == Command::kCurve)) {
      drag_owner_[reply.load_id()] = c.sink.get();
    }
    if (outcome == SimCore::Outcome::kApplied || outcome == SimCore::Outcome::kRejected) {
      if (!dir_.empty()) {
        persist::JournalRecord record;
        record.set_step(reply.applied_step());
        record.set_client_id(c.request.client_id());
        record.set_seq(c.request.seq());
        *record.mutable_command() = c.request.command();
        *record.mutable_reply() = reply;
        std::string framed = FrameRecord(record.SerializeAsString());
        journal_submitted_ += framed.size();
        batch.framed += framed;
        ++batch.records;
      }
    }
    if (outcome == SimCore::Outcome::kDuplicate) ++duplicates;
    if (outcome == SimCore::Outcome::kApplied) {
      frame_for_command_ = true;
      commanded_clients_.insert(c.request.client_id());
    }
    if (core_->TakeSaveRequest()) {
      // The Save's own record goes first; the snapshot covers it.
      batch.snapshot = MakeSnapshotBytes();
      batch.snapshot_step = core_->steps();
      reply.mutable_saved()->set_bytes(static_cast<int64_t>(batch.snapshot.size()));
    }
    if (outcome == SimCore::Outcome::kApplied || outcome == SimCore::Outcome::kRejected) {
      SessionLog().debug("session {}: client {} seq {} at step {}: code {} {}", id_,
                        reply.client_id(), reply.seq(), reply.applied_step(), reply.code(),
                        reply.message());
    }
    batch.replies.emplace_back(std::move(c.sink), std::move(reply));
  }
  UpdateCounters();
  if (duplicates > 0) {
    absl::MutexLock lock(&stats_mu_);
    counters_.duplicates += duplicates;
  }
  Deliver(std::move(batch));
}

void SessionLoop::HoldBehindBuild(std::deque<PendingCommand>& commands) {
  std::deque<PendingCommand> ahead;
  const Command& building = building_->request.command();
  for (PendingCommand& c : commands) {
    const std::string& client = c.request.client_id();
    if (SimCore::MayPassBuild(building, c.request.command()) && !held_clients_.contains(client)) {
      ahead.push_back(std::move(c));
    } else {
      held_clients_.insert(client);
      held_.push_back(std::move(c));
    }
  }
  commands.swap(ahead);
}

std::string SessionLoop::MakeSnapshotBytes() {
  persist::Snapshot snapshot;
  core_->SaveTo(&snapshot);
  snapshot.set_journal_offset(journal_submitted_);
  snapshot.set_solid_state(core_->solid().SaveState());
  last_snapshot_step_ = core_->steps();
  return FrameRecord(snapshot.SerializeAsString());
}

void SessionLoop::Deliver(PersistBatch batch) {
  if (dir_.empty()) {
    for (auto& [sink, reply] : batch.replies) {
      if (sink != nullptr) sink->Reply(reply);
    }
    return;
  }
  absl::MutexLock lock(&persist_mu_);
  persist_queue_.push_back(std::move(batch));
}

void SessionLoop::Publish(Clock::time_point now, bool early) {
  std::vector<std::shared_ptr<WatchSink>> sinks;
  bool fields = false;
  double rate = 0;
  {
    absl::MutexLock lock(&mu_);
    for (auto& [ptr, entry] : watchers_) {
      rate = std::max(rate, entry.sink->rate_hz());
      const std::string& client = entry.sink->client_id();
      if (early && !client.empty() && !commanded_clients_.contains(client)) continue;
      sinks.push_back(entry.sink);
      fields = fields || entry.sink->fields().any();
    }
    if (!early) publish_requested_ = false;
  }
  frame_for_command_ = false;
  commanded_clients_.clear();
  if (sinks.empty()) return;
  std::shared_ptr<const SurfaceSnapshot> snap = core_->MakeSnapshot(fields);
  for (auto& s : sinks) s->Offer(snap);
  last_early_step_ = snap->step;
  last_early_fields_ = snap->fields_version;
  if (early) {
    // The early frames' budget counts their writes.
    const double interval =
        std::max(1.0 / options_.max_watch_hz,
                 static_cast<double>(sinks.size()) / options_.command_frame_writes_per_second);
    earliest_publish_ = now + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(interval));
  } else {
    last_published_step_ = snap->step;
    last_published_fields_ = snap->fields_version;
    rate = std::clamp(rate > 0 ? rate : options_.watch_hz, 0.1, options_.max_watch_hz);
    next_publish_ = now + std::chrono::duration_cast<Clock::duration>(
                              std::chrono::duration<double>(1.0 / rate));
  }
  absl::MutexLock lock(&stats_mu_);
  ++counters_.frames_published;
}

void SessionLoop::UpdateProbes() {
  const ProbeHub::UpdateResult r = probes_.Update(*core_);
  contact_ms_ = r.ms;
  if (r.contact_ended && !dir_.empty()) {
    // Probe loads are not journaled: make what they did durable.
    PersistBatch batch;
    batch.snapshot = MakeSnapshotBytes();
    batch.snapshot_step = core_->steps();
    Deliver(std::move(batch));
  }
}

// ---- Persistence thread ----

void SessionLoop::Persist() {
  NameThisThread("journal");
  for (;;) {
    PersistBatch batch;
    {
      absl::MutexLock lock(&persist_mu_);
      persist_mu_.Await(absl::Condition(
          +[](SessionLoop* l) ABSL_EXCLUSIVE_LOCKS_REQUIRED(l->persist_mu_) {
            return l->persist_stop_ || !l->persist_queue_.empty();
          },
          this));
      if (persist_queue_.empty()) return;  // stopped and drained
      batch = std::move(persist_queue_.front());
      persist_queue_.pop_front();
    }
    // After a failed write nothing more is written (a record after a torn
    // one would be unreachable on recovery) and nothing more is
    // acknowledged: the session's commands fail until it is recovered.
    absl::Status s = persist_error_;
    if (s.ok() && !batch.framed.empty()) {
      s = journal_->Append(batch.framed);
      if (s.ok()) s = journal_->Sync();
    }
    bool snapshot_written = false;
    if (s.ok() && !batch.snapshot.empty()) {
      // A snapshot that cannot be written loses nothing: the previous one
      // and the journal (already durable) still recover the session. It is
      // logged and tried again at the next snapshot.
      const absl::Status snap = WriteFileAtomically(dir_, "snapshot.binpb", batch.snapshot);
      snapshot_written = snap.ok();
      if (!snap.ok()) {
        JournalLog().warn("session {}: snapshot at step {} not written: {}", id_,
                          batch.snapshot_step, snap.ToString());
        if (absl::IsResourceExhausted(snap) && options_.disk != nullptr) {
          options_.disk->ReportFull(snap.message());
        }
      }
    }
    if (!s.ok() && absl::IsResourceExhausted(s) && options_.disk != nullptr) {
      options_.disk->ReportFull(s.message());
    }
    if (!s.ok()) {
      // Nothing is acknowledged that is not durable.
      if (persist_error_.ok()) {
        JournalLog().error("session {}: persistence failed: {}", id_, s.ToString());
      }
      persist_error_ = s;
      for (auto& [sink, reply] : batch.replies) {
        if (sink == nullptr) continue;  // the server's own (a release)
        sink->Stop(absl::Status(
            absl::IsResourceExhausted(s) ? absl::StatusCode::kResourceExhausted
                                         : absl::StatusCode::kInternal,
            absl::StrCat("the journal could not be written: ", s.message())));
      }
      continue;
    }
    if (snapshot_written) {
      JournalLog().debug("session {}: snapshot at step {} ({} bytes)", id_, batch.snapshot_step,
                         batch.snapshot.size());
    }
    {
      absl::MutexLock lock(&stats_mu_);
      counters_.journal_records += batch.records;
      counters_.journal_bytes = static_cast<int64_t>(journal_->size());
      if (snapshot_written) {
        ++counters_.snapshots;
        counters_.last_snapshot_step = batch.snapshot_step;
      }
    }
    for (auto& [sink, reply] : batch.replies) {
      if (sink != nullptr) sink->Reply(reply);
    }
  }
}

}  // namespace dynsolid::server
