// A session's simulation thread and everything around it: the command
// queue (applied at step boundaries in arrival order), the fixed-step
// real-time clock with overrun accounting, frame publication to watchers,
// inspections, stats, and (with a data directory) the journal and
// snapshots written by a persistence thread.
//
// Threads:
//  - the simulation thread owns the SimCore (the solid): it alone steps,
//    applies commands, builds SurfaceSnapshots and snapshot bytes;
//  - the persistence thread appends journal records, fdatasyncs, writes
//    snapshots, and only then releases the replies that depend on them;
//  - gRPC threads call the public methods, which only enqueue or copy
//    stats under short locks; nothing here blocks on a client.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "dynsolid/service.pb.h"
#include "server/disk_space.h"
#include "server/journal.h"
#include "server/probe.h"
#include "server/sim_core.h"
#include "server/surface_codec.h"

namespace dynsolid::server {

// Receives the replies of one Commands stream. Implemented by the reactor.
class ReplySink {
 public:
  virtual ~ReplySink() = default;
  // One reply; never blocks (the reactor queues it).
  virtual void Reply(const CommandReply& reply) = 0;
  // The session is going away: finish the stream with `status`.
  virtual void Stop(const absl::Status& status) = 0;
};

// One watcher of the session's surface. Implemented by the Watch reactor.
class WatchSink {
 public:
  virtual ~WatchSink() = default;
  // A new snapshot: the watcher keeps only the latest (replacing one it has
  // not started sending counts as skipped). Never blocks.
  virtual void Offer(std::shared_ptr<const SurfaceSnapshot> snapshot) = 0;
  virtual void Stop(const absl::Status& status) = 0;
  virtual WatcherStats Stats() const = 0;
  // Its id, set by AddWatcher before the first Offer.
  virtual void set_watcher_id(int64_t id) = 0;
  virtual const FieldChoice& fields() const = 0;
  virtual double rate_hz() const = 0;
  // WatchRequest.client_id: the client whose commands it is shown at once
  // (empty: every client's).
  virtual const std::string& client_id() const = 0;
};

// Real-time debt the loop catches up by stepping back to back; beyond it,
// it gives the debt up (SessionStats.overruns, steps_dropped).
inline constexpr std::chrono::milliseconds kCatchUp{25};

struct LoopOptions {
  // Default and largest watch rate, frames per second.
  double watch_hz = 60;
  double max_watch_hz = 240;
  // Frames sent early because a command was applied (frame_for_command_),
  // to the watchers of the clients whose commands were applied and to those
  // with no client_id: at most max_watch_hz, and at most this many such
  // frame writes per second (64 watchers with no client_id: 31 early frames
  // a second), so that many watchers do not turn commands into a flood.
  double command_frame_writes_per_second = 2000;
  int max_watchers = 64;
  // Added to the nice value of the thread that builds a solid off the loop
  // (a paint, an edit, an undo across one), 0..19: on busy cores a build
  // takes longer rather than the simulation losing steps. 0: the loop's.
  int build_nice = 10;
  // Per client_id: commands per second (token bucket, burst of one second).
  double commands_per_second = 1000;
  // Write a snapshot every this many steps (with a data directory).
  int64_t snapshot_every_steps = 20000;
  CoreOptions core;
  // The data disk's state (with a data directory; may be null): told when
  // a journal reservation or a write finds it full.
  std::shared_ptr<DiskSpace> disk;
};

// Journal space reserved ahead (JournalWriter::Reserve) before a command is
// applied: the command's bytes plus kJournalSlack (its reply and framing),
// in steps of at least kJournalReserveStep.
inline constexpr uint64_t kJournalSlack = 16 << 10;
inline constexpr uint64_t kJournalReserveStep = 64 << 10;

// State recovered from a session directory (see persistence.h).
struct Recovered {
  uint64_t journal_end = 0;  // where appending resumes
  int64_t journal_records = 0;
  int64_t last_snapshot_step = -1;
};

class SessionLoop {
 public:
  // Starts the simulation thread (and, with a non-empty `dir`, the
  // persistence thread appending to dir/journal from recovered.journal_end).
  static absl::StatusOr<std::unique_ptr<SessionLoop>> Start(std::string session_id,
                                                            std::unique_ptr<SimCore> core,
                                                            LoopOptions options, std::string dir,
                                                            Recovered recovered);
  ~SessionLoop();  // Stop(Unavailable "the session is closed")
  SessionLoop(const SessionLoop&) = delete;
  SessionLoop& operator=(const SessionLoop&) = delete;

  // Stops stepping, writes a last snapshot (with a data directory), flushes
  // the journal, answers pending inspections and finishes every watcher and
  // command stream with `status`. Idempotent.
  void Stop(const absl::Status& status);

  // ---- Commands. Rate check (per client_id, call once per command). Keeps
  // each client's order: once a seq is refused, the client's higher seqs
  // are refused too (without spending tokens) until that seq comes again
  // and passes, so a pipelining client's resends apply in seq order.
  bool AllowCommand(const std::string& client_id, uint64_t seq);
  // Queues a command; its reply goes to `sink` (after it is durable).
  void Submit(const CommandRequest& request, std::shared_ptr<ReplySink> sink);
  // Command streams to finish when the session stops. Register fails with
  // Unavailable once stopped.
  absl::Status RegisterCommandStream(std::shared_ptr<ReplySink> sink);
  void UnregisterCommandStream(ReplySink* sink);
  void CountRateLimited() { rate_limited_.fetch_add(1); }

  // ---- Watchers. ResourceExhausted at max_watchers, Unavailable once
  // stopped. Returns the watcher id.
  absl::StatusOr<int64_t> AddWatcher(std::shared_ptr<WatchSink> sink);
  // Removes it and adds its counts to the session totals.
  void RemoveWatcher(WatchSink* sink);

  // ---- Inspection: `done` is called once, from the simulation thread (or
  // from Stop with Unavailable).
  // `cancelled` (optional) is polled while the inspection waits for its
  // step; once it returns true, `done` gets Cancelled.
  void Inspect(const InspectRequest& request,
               std::function<void(absl::StatusOr<InspectReply>)> done,
               std::function<bool()> cancelled = nullptr);

  // Runs `fn` on the simulation thread at the next step boundary with the
  // core (read-only), or with nullptr when the session stops first.
  void Query(std::function<void(const SimCore*)> fn);

  SessionStats Stats() const;
  double time_step() const { return time_step_; }
  // The session's haptic probes (probe.h; rpc Probe).
  ProbeHub& probes() { return probes_; }
  // Shared by this session's watchers' encoders.
  const std::shared_ptr<EncodeCache>& encode_cache() const { return encode_cache_; }

 private:
  SessionLoop(std::string session_id, std::unique_ptr<SimCore> core, LoopOptions options,
              std::string dir, Recovered recovered);
  void Run();
  void Persist();

  struct PendingCommand {
    CommandRequest request;
    std::shared_ptr<ReplySink> sink;
  };
  struct PendingInspect {
    InspectRequest request;
    std::function<void(absl::StatusOr<InspectReply>)> done;
    std::function<bool()> cancelled;
    std::function<void(const SimCore*)> query;  // set: a Query instead
  };
  // Work for the persistence thread: records to append and sync, maybe a
  // snapshot to write, then replies to release.
  struct PersistBatch {
    std::string framed;
    int64_t records = 0;
    std::string snapshot;  // framed Snapshot, empty for none
    int64_t snapshot_step = -1;
    std::vector<std::pair<std::shared_ptr<ReplySink>, CommandReply>> replies;
  };

  // The simulation thread (Run) in steps. Its real-time clock: a step h,
  // the debt it catches up (kCatchUp), when the next step is due (anchored:
  // counted from a step, not from a pause), and the steps counted for
  // steps_per_second since rate_start.
  struct Schedule {
    std::chrono::steady_clock::duration h{};
    std::chrono::steady_clock::duration catch_up{};
    std::chrono::steady_clock::time_point next_step{};
    bool anchored = false;
    std::chrono::steady_clock::time_point rate_start{};
    int64_t rate_steps = 0;
    // While paused: probes refresh every h.
    std::chrono::steady_clock::time_point next_probe_refresh{};
  };
  // What a wake-up of the simulation thread takes from the queues.
  struct Wakeup {
    bool stop = false;
    std::deque<PendingCommand> commands;
    bool publish_requested = false;
    bool has_watchers = false;
  };
  // Waits until there is work (a command, an inspection, a finished build,
  // an ended stream, a step or a frame due, a stop) and takes it.
  Wakeup WaitForWork(const Schedule& schedule);
  // At a stop: every command not applied (the building one, the held ones,
  // `commands`) goes back to the front of commands_, in order.
  void RequeueUnapplied(std::deque<PendingCommand>& commands);
  // Puts `commands` in the order they apply: after a finished build (which
  // it returns) its command and those held behind it first; with a build
  // under way only those that may go ahead of it; then the releases of
  // ended streams' drags.
  std::shared_ptr<SimCore::Prebuilt> OrderCommands(std::deque<PendingCommand>& commands);
  // Steps once if a step is due at `now` (after a pause the clock starts
  // again from `now`), then counts the lag, answers the inspections waiting
  // for the step and writes a periodic snapshot. Returns the time now
  // (after the step, if one ran).
  std::chrono::steady_clock::time_point StepIfDue(Schedule& schedule,
                                                  std::chrono::steady_clock::time_point now);
  // A frame to the watchers if one is due (Publish).
  void PublishIfDue(std::chrono::steady_clock::time_point now, bool publish_requested);
  // SessionStats.steps_per_second, once a second.
  void CountStepRate(Schedule& schedule, std::chrono::steady_clock::time_point now);

  // Simulation-thread helpers. ApplyCommands applies commands in order
  // until one needs a solid built (SimCore::NeedsBuild): that one starts its
  // build on a thread of its own, and it and the commands after it wait
  // (held_) while the loop goes on stepping, but for those that may go
  // ahead of the build (HoldBehindBuild: loads and drags of clients with
  // nothing waiting); `prebuilt` is the finished build for the first
  // command.
  void ApplyCommands(std::deque<PendingCommand>& commands,
                     std::shared_ptr<SimCore::Prebuilt> prebuilt = nullptr);
  // With a build under way: moves to held_ the commands that must wait for
  // it, and leaves in `commands`, in order, those that may go ahead
  // (SimCore::MayPassBuild, from a client with nothing held or building).
  void HoldBehindBuild(std::deque<PendingCommand>& commands);
  std::string MakeSnapshotBytes();
  // A frame to every watcher, or (early) to the watchers of the clients in
  // commanded_clients_ and those with no client_id.
  void Publish(std::chrono::steady_clock::time_point now, bool early);
  void AnswerInspects(bool all_unavailable);
  void RecordStep(double ms);
  // The probes' work at a step boundary (probe.h); with a data directory a
  // snapshot when the last probe that pushed has left.
  void UpdateProbes();
  double contact_ms_ = -1;  // the last UpdateProbes' time, -1: none
  // Copies the core's state into the stats (before replies and inspections
  // go out, so a client never sees stats older than an answer it got).
  void UpdateCounters();
  void Deliver(PersistBatch batch);

  const std::string id_;
  const LoopOptions options_;
  const std::string dir_;
  const double time_step_;
  std::unique_ptr<SimCore> core_;  // simulation thread only (after Start)
  const std::shared_ptr<EncodeCache> encode_cache_ = std::make_shared<EncodeCache>();
  ProbeHub probes_;

  // Queues and membership.
  mutable absl::Mutex mu_;
  absl::CondVar wake_;
  bool stop_ ABSL_GUARDED_BY(mu_) = false;
  bool stopped_ ABSL_GUARDED_BY(mu_) = false;  // Stop finished
  absl::Status stop_status_ ABSL_GUARDED_BY(mu_);
  std::deque<PendingCommand> commands_ ABSL_GUARDED_BY(mu_);
  std::deque<PendingInspect> inspects_ ABSL_GUARDED_BY(mu_);
  bool publish_requested_ ABSL_GUARDED_BY(mu_) = false;
  struct WatcherEntry {
    std::shared_ptr<WatchSink> sink;
    int64_t id;
  };
  absl::flat_hash_map<WatchSink*, WatcherEntry> watchers_ ABSL_GUARDED_BY(mu_);
  int64_t next_watcher_id_ ABSL_GUARDED_BY(mu_) = 1;
  absl::flat_hash_map<ReplySink*, std::shared_ptr<ReplySink>> command_streams_
      ABSL_GUARDED_BY(mu_);
  struct Bucket {
    double tokens = 0;
    uint64_t refused_from = 0;  // lowest refused seq not yet let through (0: none)
    std::chrono::steady_clock::time_point last;
  };
  absl::flat_hash_map<std::string, Bucket> buckets_ ABSL_GUARDED_BY(mu_);

  // A solid being built for a command (ApplyCommands).
  std::shared_ptr<SimCore::Prebuilt> built_ ABSL_GUARDED_BY(mu_);
  bool build_done_ ABSL_GUARDED_BY(mu_) = false;
  // Command streams that ended: the drags and curves they started are
  // released (ReleaseDragsOf).
  std::vector<ReplySink*> ended_streams_ ABSL_GUARDED_BY(mu_);

  // Simulation-thread state.
  std::optional<PendingCommand> building_;  // the command whose solid is being built
  std::thread builder_;
  std::deque<PendingCommand> held_;  // commands behind it, in order
  absl::flat_hash_set<std::string> held_clients_;  // their clients and building_'s
  // Drags and curves by load id -> the command stream that started them.
  absl::flat_hash_map<int64_t, ReplySink*> drag_owner_;
  std::vector<ReplySink*> streams_to_release_;  // ended, waiting for a build
  // Queues remove_load commands (client kReleaseClient) for the drags and
  // curves the ended streams started that are still acting.
  void ReleaseDragsOf(std::deque<PendingCommand>& commands);
  std::vector<PendingInspect> waiting_inspects_;
  int64_t last_published_step_ = -1;
  int64_t last_published_fields_ = -1;
  std::chrono::steady_clock::time_point next_publish_;
  // A command was applied since the last frame: the next frame of the
  // watchers of the clients that sent one (commanded_clients_) and of those
  // with no client_id goes out after the next step, not at the watchers'
  // rate, but not before earliest_publish_
  // (LoopOptions::command_frame_writes_per_second), so a client sees what
  // it did within a step or two.
  bool frame_for_command_ = false;
  absl::flat_hash_set<std::string> commanded_clients_;
  // The step and fields of the last frame to any watcher (early or not).
  int64_t last_early_step_ = -1;
  int64_t last_early_fields_ = -1;
  std::chrono::steady_clock::time_point earliest_publish_;
  uint64_t journal_submitted_ = 0;  // logical journal size incl. queued
  int64_t last_snapshot_step_ = -1;

  // Persistence thread.
  std::unique_ptr<JournalWriter> journal_;
  absl::Mutex persist_mu_;
  std::deque<PersistBatch> persist_queue_ ABSL_GUARDED_BY(persist_mu_);
  bool persist_stop_ ABSL_GUARDED_BY(persist_mu_) = false;
  std::thread persist_thread_;
  absl::Status persist_error_;  // persistence thread only

  // Stats (written by the simulation and persistence threads).
  mutable absl::Mutex stats_mu_;
  struct Counters {
    int64_t step = 0;
    double time = 0;
    bool paused = false;
    int64_t steps_remaining = 0;
    std::string last_error;
    int64_t rollbacks = 0;
    int64_t fields_version = 0;
    int64_t applied = 0, rejected = 0, duplicates = 0;
    int64_t steps_behind = 0, overruns = 0, steps_dropped = 0;
    double steps_per_second = 0;
    int64_t frames_published = 0;
    // Totals of watchers that left.
    int64_t gone_sent = 0, gone_skipped = 0, gone_keyframes = 0, gone_bytes = 0;
    int64_t journal_records = 0, journal_bytes = 0, snapshots = 0, last_snapshot_step = 0;
    int32_t undo_depth = 0, redo_depth = 0;
    int64_t history_bytes = 0, history_limit = 0, topology_version = 0;
    double hold_ms = 0;
    int32_t control_cells = 0, control_vertices = 0;
    int64_t builds = 0;
    double build_ms = 0, build_cpu_ms = 0, build_wait_ms = 0;
    std::deque<double> step_ms;  // last 1000
    std::vector<std::pair<std::string, std::deque<double>>> phases;
  } counters_ ABSL_GUARDED_BY(stats_mu_);
  std::atomic<int64_t> rate_limited_{0};

  std::thread sim_thread_;
};

}  // namespace dynsolid::server
