// Haptic probes of a session (service.proto rpc Probe; docs/haptic.md).
//
// A probe stream sends poses (with the coupling force the bridge rendered)
// and receives, once per step, a ContactModel of the surface under the
// probe. Two sides share each stream's ProbeChannel:
//  - the reactor (gRPC threads) checks each pose on arrival (finite, seq
//    above the last accepted one, force within the limit) and keeps only
//    the newest accepted one (latest wins); it never touches the solid;
//  - the session's simulation thread calls ProbeHub::Update at every step
//    boundary (and about every h while paused): it takes each probe's
//    newest pose, refuses one far outside the solid's bounds, finds the
//    closest surface point, computes the contact model (Solid::
//    ContactResponseAt), sets the reaction loads (Solid::SetContactLoads:
//    minus each reported coupling force, at the material point of the
//    model it was rendered from) and offers each stream its reply (one
//    write in flight; a newer reply replaces one not yet written).
// With no probe attached Update returns at once (after removing the last
// probe's load once): a session without a probe does no contact work and
// its stats have no "contact" phase.
//
// Contact loads are real-time input, like a hand on the solid: they are
// not journaled, so a session recovered from its journal replays its
// commands without them (docs/haptic.md "Persistence"); the session loop
// writes a snapshot when the last probe that pushed leaves, which makes
// what the probes did durable.
#pragma once

#include <grpcpp/grpcpp.h>

#include <Eigen/Core>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "dynsolid/service.pb.h"
#include "server/parsed_request.h"

namespace dynsolid::server {

class SimCore;

struct ProbeLimits {
  // Probe streams per session (RESOURCE_EXHAUSTED beyond).
  int max_probes = 4;
  // Largest |coupling_force| accepted, newtons.
  double max_force = 1e4;
  // A pose farther than this many times the solid's largest extent outside
  // its current bounding box is refused ("far out of the scene's bounds").
  double far_factor = 2.0;
  // Default near distance as a fraction of the largest extent.
  double near_fraction = 0.1;
  // Default horizon tau, seconds (docs/model.md 9).
  double horizon = 0.03;
  // A pose older than this (wall time, seconds) no longer applies its
  // force: a bridge that stopped sending does not keep pushing.
  double pose_timeout = 0.25;
};

// One probe stream's shared state. Thread-safe.
class ProbeChannel {
 public:
  // `reactor` receives StartWrite/Finish calls (never under the lock).
  ProbeChannel(grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* reactor, int64_t id,
               double near_distance, double horizon)
      : reactor_(reactor), id_(id), near_distance_(near_distance), horizon_(horizon) {}
  ProbeChannel(const ProbeChannel&) = delete;
  ProbeChannel& operator=(const ProbeChannel&) = delete;

  int64_t id() const { return id_; }
  double near_distance() const { return near_distance_; }  // <= 0: the default
  double horizon() const { return horizon_; }

  // ---- Reactor side.
  // Checks a pose (finite, seq, force): accepted (kept as the newest) or
  // refused (queued for the next reply). Returns whether it was accepted.
  bool Receive(const ProbePose& pose, const ProbeLimits& limits);
  void OnWriteDone(bool ok);
  // The client half-closed: finish once no write is in flight.
  void ReadsDone();
  // Ends the stream with `status` (idempotent).
  void Stop(const absl::Status& status);
  bool ended() const;

  // ---- Simulation-thread side.
  // The newest accepted pose not taken yet.
  std::optional<ProbePose> TakePose();
  // Refuses a pose the simulation thread found bad (out of bounds).
  void Reject(uint64_t seq, const absl::Status& status);
  // Sends `reply` (its rejections are filled in here) or keeps it as the
  // next one if a write is in flight (replacing an unsent one).
  void Offer(ProbeReply reply);

  ProbeStats Stats() const;
  // Set by the simulation thread for the stats.
  void SetApplied(const Eigen::Vector3d& force, uint32_t buttons);

 private:
  void AddRejectionLocked(uint64_t seq, const absl::Status& status)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  bool TakeFinishLocked(grpc::Status* status) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* const reactor_;
  const int64_t id_;
  const double near_distance_;
  const double horizon_;

  mutable absl::Mutex mu_;
  std::optional<ProbePose> pose_ ABSL_GUARDED_BY(mu_);
  uint64_t last_seq_ ABSL_GUARDED_BY(mu_) = 0;
  std::vector<PoseRejection> rejections_ ABSL_GUARDED_BY(mu_);
  int64_t rejected_total_ ABSL_GUARDED_BY(mu_) = 0;
  ProbeReply current_;  // the write in flight (set under mu_, read by gRPC)
  ProbeReply pending_ ABSL_GUARDED_BY(mu_);
  bool has_pending_ ABSL_GUARDED_BY(mu_) = false;
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  bool reads_done_ ABSL_GUARDED_BY(mu_) = false;
  bool done_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status status_ ABSL_GUARDED_BY(mu_);
  // Stats.
  int64_t received_ ABSL_GUARDED_BY(mu_) = 0, accepted_ ABSL_GUARDED_BY(mu_) = 0,
                    superseded_ ABSL_GUARDED_BY(mu_) = 0, models_sent_ ABSL_GUARDED_BY(mu_) = 0,
                    replies_sent_ ABSL_GUARDED_BY(mu_) = 0,
                    replies_skipped_ ABSL_GUARDED_BY(mu_) = 0;
  uint32_t buttons_ ABSL_GUARDED_BY(mu_) = 0;
  Eigen::Vector3d applied_ ABSL_GUARDED_BY(mu_) = Eigen::Vector3d::Zero();
};

// The probes of one session. Attach/Detach/Stats from any thread; Update
// from the simulation thread only.
class ProbeHub {
 public:
  explicit ProbeHub(ProbeLimits limits = {});
  ~ProbeHub();  // waits for a contact stiffness build under way
  ProbeHub(const ProbeHub&) = delete;
  ProbeHub& operator=(const ProbeHub&) = delete;

  const ProbeLimits& limits() const { return limits_; }
  // Called after a probe attaches (the session loop wakes its thread).
  void set_wake(std::function<void()> wake) { wake_ = std::move(wake); }

  // A new probe stream: ResourceExhausted at max_probes, Unavailable once
  // stopped, InvalidArgument for bad options.
  absl::StatusOr<std::shared_ptr<ProbeChannel>> Attach(
      grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* reactor, const ProbeOptions& options);
  // Makes an attached channel visible to the simulation thread (after the
  // reactor can route its OnWriteDone to it).
  void Activate(const std::shared_ptr<ProbeChannel>& channel);
  void Detach(ProbeChannel* channel);
  // Ends every stream with `status`; later Attach calls fail with it.
  void StopAll(const absl::Status& status);

  // Whether a probe is attached, or a load of a probe that left is still
  // on the solid (Update has work).
  bool busy() const { return attached_.load() > 0 || loads_on_; }

  struct UpdateResult {
    // Wall time of the contact work, ms; -1 when there was none.
    double ms = -1;
    // The last probe that pushed left and its load was removed.
    bool contact_ended = false;
  };
  // Simulation thread, before a step (`stepping`) or at a paused refresh.
  UpdateResult Update(SimCore& core);

  void FillStats(SessionStats* stats) const;

 private:
  // Simulation-thread state of one probe.
  struct Sim {
    std::shared_ptr<ProbeChannel> channel;
    std::optional<ProbePose> pose;                    // the newest accepted and in bounds
    std::chrono::steady_clock::time_point pose_time;  // when it was taken
    // Contact points of recent models: (step, quad, u, v).
    struct Located {
      int64_t step;
      int32_t quad;
      double u, v;
    };
    std::deque<Located> recent;
    int64_t topology_version = -1;
    Eigen::Vector3d applied = Eigen::Vector3d::Zero();  // load set at the last update
    std::optional<Located> applied_at;
  };

  const ProbeLimits limits_;
  std::function<void()> wake_;
  std::atomic<int> attached_{0};

  mutable absl::Mutex mu_;
  std::vector<std::shared_ptr<ProbeChannel>> channels_ ABSL_GUARDED_BY(mu_);  // attached
  std::vector<std::shared_ptr<ProbeChannel>> active_ ABSL_GUARDED_BY(mu_);    // activated
  int64_t next_id_ ABSL_GUARDED_BY(mu_) = 1;
  int64_t total_ ABSL_GUARDED_BY(mu_) = 0;
  bool stopped_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status stop_status_ ABSL_GUARDED_BY(mu_);

  // The contact stiffness (Solid::ContactCacheJob), built on a thread of its
  // own when a probe needs it: a build on the loop would hold it (0.2 s on
  // block3, seconds after a topology edit). Meanwhile models go out without
  // stiffness (the bridge renders its coupling alone). Simulation thread
  // only, but `contact_done_`.
  void TendContactBuild(SimCore& core);
  struct ContactBuild;  // probe.cc
  std::unique_ptr<ContactBuild> contact_;
  bool contact_wanted_ = false;  // a probe asked for a model while stale

  // Simulation thread only.
  std::vector<Sim> sims_;
  bool loads_on_ = false;  // read by busy() on the simulation thread only
  bool pushed_ = false;    // some probe applied a force since the last contact_ended
};

}  // namespace dynsolid::server
