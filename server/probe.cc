#include "server/probe.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "server/grpc_status.h"
#include "server/log.h"
#include "server/session_loop.h"
#include "server/sim_core.h"
#include "server/vec3.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::server {
namespace {

constexpr size_t kMaxRejectionsPerReply = 16;
constexpr size_t kRecentModels = 256;

Eigen::Vector3d FromVec3(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

// ------------------------------------------------------------ ProbeChannel

bool ProbeChannel::Receive(const ProbePose& pose, const ProbeLimits& limits) {
  absl::Status s = scene::ValidateValues(pose, "pose");
  absl::MutexLock lock(&mu_);
  ++received_;
  if (s.ok() && pose.seq() <= last_seq_) {
    s = absl::OutOfRangeError(absl::StrCat("pose.seq: ", pose.seq(),
                                           " is not above the last accepted pose's ", last_seq_));
  }
  if (s.ok()) {
    const double f = FromVec3(pose.coupling_force()).norm();
    if (f > limits.max_force) {
      s = absl::InvalidArgumentError(absl::StrCat("pose.coupling_force: |f| = ", f,
                                                  " N is above the server's limit of ",
                                                  limits.max_force, " N"));
    }
  }
  if (!s.ok()) {
    AddRejectionLocked(pose.seq(), s);
    return false;
  }
  ++accepted_;
  if (pose_.has_value()) ++superseded_;
  pose_ = pose;
  last_seq_ = pose.seq();
  buttons_ = pose.buttons();
  return true;
}

void ProbeChannel::AddRejectionLocked(uint64_t seq, const absl::Status& status) {
  ++rejected_total_;
  if (rejections_.size() >= kMaxRejectionsPerReply) return;
  PoseRejection r;
  r.set_seq(seq);
  r.set_code(static_cast<int32_t>(status.code()));
  r.set_message(std::string(status.message()));
  rejections_.push_back(std::move(r));
}

void ProbeChannel::Reject(uint64_t seq, const absl::Status& status) {
  absl::MutexLock lock(&mu_);
  AddRejectionLocked(seq, status);
}

std::optional<ProbePose> ProbeChannel::TakePose() {
  absl::MutexLock lock(&mu_);
  std::optional<ProbePose> p = std::move(pose_);
  pose_.reset();
  return p;
}

void ProbeChannel::Offer(ProbeReply reply) {
  bool write = false;
  {
    absl::MutexLock lock(&mu_);
    if (done_) return;
    reply.set_probe_id(id_);
    reply.set_last_pose_seq(last_seq_);
    reply.set_rejected_total(rejected_total_);
    for (PoseRejection& r : rejections_) *reply.add_rejected() = std::move(r);
    rejections_.clear();
    if (reply.has_model()) ++models_sent_;
    if (writing_) {
      if (has_pending_) {
        // Keep the rejections of the reply replaced, in the order the poses
        // came: its (older) ones first.
        ++replies_skipped_;
        google::protobuf::RepeatedPtrField<PoseRejection> kept =
            std::move(*pending_.mutable_rejected());
        for (PoseRejection& r : *reply.mutable_rejected()) {
          if (kept.size() < static_cast<int>(kMaxRejectionsPerReply)) *kept.Add() = std::move(r);
        }
        *reply.mutable_rejected() = std::move(kept);
      }
      pending_ = std::move(reply);
      has_pending_ = true;
      return;
    }
    current_ = std::move(reply);
    writing_ = true;
    write = true;
  }
  if (write) reactor_->StartWrite(&current_);
}

void ProbeChannel::OnWriteDone(bool ok) {
  bool write = false;
  bool finish = false;
  grpc::Status g;
  {
    absl::MutexLock lock(&mu_);
    writing_ = false;
    if (ok) {
      ++replies_sent_;
    } else if (!done_) {
      done_ = true;
      status_ = absl::UnavailableError("the probe stream broke");
    }
    if (!done_ && has_pending_) {
      current_ = std::move(pending_);
      has_pending_ = false;
      writing_ = true;
      write = true;
    } else {
      finish = TakeFinishLocked(&g);
    }
  }
  if (write) reactor_->StartWrite(&current_);
  if (finish) reactor_->Finish(g);
}

void ProbeChannel::ReadsDone() {
  grpc::Status g;
  bool finish = false;
  {
    absl::MutexLock lock(&mu_);
    reads_done_ = true;
    if (!done_) {
      done_ = true;
      status_ = absl::OkStatus();
    }
    has_pending_ = false;
    finish = TakeFinishLocked(&g);
  }
  if (finish) reactor_->Finish(g);
}

void ProbeChannel::Stop(const absl::Status& status) {
  grpc::Status g;
  bool finish = false;
  {
    absl::MutexLock lock(&mu_);
    if (!done_) {
      done_ = true;
      status_ = status;
    }
    has_pending_ = false;
    finish = TakeFinishLocked(&g);
  }
  if (finish) reactor_->Finish(g);
}

bool ProbeChannel::ended() const {
  absl::MutexLock lock(&mu_);
  return done_;
}

bool ProbeChannel::TakeFinishLocked(grpc::Status* g) {
  if (finished_ || writing_ || !done_) return false;
  *g = ToGrpcStatus(status_);
  finished_ = true;
  return true;
}

void ProbeChannel::SetApplied(const Eigen::Vector3d& force, uint32_t buttons) {
  absl::MutexLock lock(&mu_);
  applied_ = force;
  (void)buttons;
}

ProbeStats ProbeChannel::Stats() const {
  absl::MutexLock lock(&mu_);
  ProbeStats s;
  s.set_probe_id(id_);
  s.set_poses_received(received_);
  s.set_poses_accepted(accepted_);
  s.set_poses_rejected(rejected_total_);
  s.set_poses_superseded(superseded_);
  s.set_models_sent(models_sent_);
  s.set_replies_sent(replies_sent_);
  s.set_replies_skipped(replies_skipped_);
  s.set_last_pose_seq(last_seq_);
  s.set_buttons(buttons_);
  *s.mutable_applied_force() = ToVec3(applied_);
  return s;
}

// ---------------------------------------------------------------- ProbeHub

absl::StatusOr<std::shared_ptr<ProbeChannel>> ProbeHub::Attach(
    grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* reactor, const ProbeOptions& options) {
  if (absl::Status s = scene::ValidateValues(options, "options"); !s.ok()) return s;
  if (options.near_distance() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.near_distance: must be >= 0 (0: the default), got ", options.near_distance()));
  }
  if (options.horizon() != 0 && !(options.horizon() >= 0.001 && options.horizon() <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.horizon: must be in [0.001, 1] s (0: the default ", limits_.horizon,
                     "), got ", options.horizon()));
  }
  std::shared_ptr<ProbeChannel> channel;
  {
    absl::MutexLock lock(&mu_);
    if (stopped_) return stop_status_;
    if (static_cast<int>(channels_.size()) >= limits_.max_probes) {
      return absl::ResourceExhaustedError(
          absl::StrCat("the session already has its maximum of ", limits_.max_probes, " probes"));
    }
    channel =
        std::make_shared<ProbeChannel>(reactor, next_id_++, options.near_distance(),
                                       options.horizon() > 0 ? options.horizon() : limits_.horizon);
    channels_.push_back(channel);
    ++total_;
  }
  return channel;
}

void ProbeHub::Activate(const std::shared_ptr<ProbeChannel>& channel) {
  {
    absl::MutexLock lock(&mu_);
    if (std::find(channels_.begin(), channels_.end(), channel) == channels_.end()) return;
    active_.push_back(channel);
    attached_.fetch_add(1);
  }
  if (wake_) wake_();
}

void ProbeHub::Detach(ProbeChannel* channel) {
  std::shared_ptr<ProbeChannel> gone;  // released after the lock
  {
    absl::MutexLock lock(&mu_);
    auto it = std::find_if(channels_.begin(), channels_.end(),
                           [channel](const auto& c) { return c.get() == channel; });
    if (it == channels_.end()) return;
    gone = std::move(*it);
    channels_.erase(it);
    auto a = std::find(active_.begin(), active_.end(), gone);
    if (a != active_.end()) {
      active_.erase(a);
      attached_.fetch_sub(1);
    }
  }
  if (wake_) wake_();  // the loop removes the probe's load at once
}

void ProbeHub::StopAll(const absl::Status& status) {
  std::vector<std::shared_ptr<ProbeChannel>> channels;
  {
    absl::MutexLock lock(&mu_);
    if (!stopped_) {
      stopped_ = true;
      stop_status_ = status;
    }
    channels = channels_;
  }
  for (auto& c : channels) c->Stop(status);
}

struct ProbeHub::ContactBuild {
  std::thread builder;
  std::atomic<bool> done{false};
  std::shared_ptr<solid::Solid> solid;  // kept alive for the build
  absl::StatusOr<std::shared_ptr<solid::Solid::PreparedContact>> built =
      absl::UnknownError("none");
  std::chrono::steady_clock::time_point started;
  int64_t epoch = -1;
  // The (solid, epoch) whose build failed: not tried again.
  const solid::Solid* failed_solid = nullptr;
  int64_t failed_epoch = -1;
};

ProbeHub::ProbeHub(ProbeLimits limits)
    : limits_(limits), contact_(std::make_unique<ContactBuild>()) {}

ProbeHub::~ProbeHub() {
  if (contact_->builder.joinable()) contact_->builder.join();
}

void ProbeHub::TendContactBuild(SimCore& core) {
  solid::Solid& solid = core.solid();
  ContactBuild& b = *contact_;
  if (b.builder.joinable() && b.done.load(std::memory_order_acquire)) {
    b.builder.join();
    b.done.store(false);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - b.started)
            .count();
    if (b.built.ok()) {
      const bool installed = solid.InstallContactCache(*b.built);
      SessionLog().info("contact stiffness built off the loop in {:.0f} ms{}", ms,
                        installed ? "" : " (the solid changed meanwhile: dropped)");
    } else {
      SessionLog().warn("no contact stiffness: {}", b.built.status().ToString());
      b.failed_solid = b.solid.get();
      b.failed_epoch = b.epoch;
    }
    b.built = absl::UnknownError("none");
    b.solid.reset();
  }
  if (contact_wanted_ && !b.builder.joinable() && solid.ContactCacheStale() &&
      !(b.failed_solid == &solid && b.failed_epoch == solid.contact_epoch())) {
    b.solid = core.shared_solid();
    b.epoch = solid.contact_epoch();
    b.started = std::chrono::steady_clock::now();
    b.builder = std::thread([&b, wake = wake_, job = solid.ContactCacheJob()] {
      b.built = job();
      b.done.store(true, std::memory_order_release);
      if (wake) wake();
    });
  }
  contact_wanted_ = false;
}

ProbeHub::UpdateResult ProbeHub::Update(SimCore& core) {
  UpdateResult result;
  std::vector<std::shared_ptr<ProbeChannel>> channels;
  if (attached_.load() > 0) {
    absl::MutexLock lock(&mu_);
    channels = active_;
  }
  if (channels.empty() && sims_.empty() && !loads_on_) return result;
  const auto t0 = std::chrono::steady_clock::now();
  solid::Solid& solid = core.solid();
  TendContactBuild(core);  // a finished build installed

  // Follow the attached set (in attach order).
  std::vector<Sim> sims;
  sims.reserve(channels.size());
  for (auto& c : channels) {
    auto it =
        std::find_if(sims_.begin(), sims_.end(), [&](const Sim& s) { return s.channel == c; });
    if (it != sims_.end()) {
      sims.push_back(std::move(*it));
    } else {
      Sim s;
      s.channel = c;
      sims.push_back(std::move(s));
    }
  }
  sims_ = std::move(sims);

  const int64_t step = solid.steps();
  const int64_t topology = solid.topology_version();
  const solid::Solid::Bounds bounds = solid.SurfaceBounds();
  const double extent = (bounds.max - bounds.min).maxCoeff();
  const double far = limits_.far_factor * extent;
  std::vector<solid::Solid::ContactLoad> loads;
  for (Sim& s : sims_) {
    if (s.topology_version != topology) {
      s.recent.clear();  // quads of another topology
      s.applied_at.reset();
      s.topology_version = topology;
    }
    if (std::optional<ProbePose> p = s.channel->TakePose()) {
      const Eigen::Vector3d x = FromVec3(p->position());
      const Eigen::Vector3d lo = bounds.min.array() - far, hi = bounds.max.array() + far;
      if ((x.array() < lo.array()).any() || (x.array() > hi.array()).any()) {
        s.channel->Reject(p->seq(),
                          absl::OutOfRangeError(absl::StrCat(
                              "pose.position (", x.x(), ", ", x.y(), ", ", x.z(), ") is more than ",
                              limits_.far_factor, " times the solid's extent (", extent,
                              " m) outside its bounds")));
      } else {
        s.pose = std::move(p);
        s.pose_time = t0;
      }
    }
    // A pose not renewed for pose_timeout: its force no longer acts (a
    // bridge that stopped sending); the model still follows the last one.
    const bool fresh =
        s.pose.has_value() &&
        std::chrono::duration<double>(t0 - s.pose_time).count() <= limits_.pose_timeout;
    ProbeReply reply;
    reply.set_step(step);
    reply.set_time(solid.time());
    std::optional<Sim::Located> here;
    if (s.pose.has_value()) {
      const Eigen::Vector3d x = FromVec3(s.pose->position());
      absl::StatusOr<solid::Solid::SurfacePoint> c = solid.ClosestSurfacePoint(x);
      const double near = s.channel->near_distance() > 0 ? s.channel->near_distance()
                                                         : limits_.near_fraction * extent;
      if (c.ok() && c->distance <= near) {
        here = Sim::Located{step, c->quad, c->u, c->v};
        ContactModel* m = reply.mutable_model();
        m->set_step(step);
        m->set_time(solid.time());
        m->set_pose_seq(s.pose->seq());
        *m->mutable_point() = ToVec3(c->point);
        *m->mutable_material_point() = ToVec3(c->material_point);
        *m->mutable_normal() = ToVec3(c->normal);
        m->set_distance(c->distance);
        m->set_surface_quad(c->quad);
        m->set_quad_u(c->u);
        m->set_quad_v(c->v);
        m->set_topology_version(topology);
        m->set_horizon(s.channel->horizon());
        absl::StatusOr<solid::Solid::ContactResponse> r =
            solid.ContactResponseAt(*c, s.channel->horizon(), /*build_if_stale=*/false);
        if (r.ok()) {
          m->set_stiffness(r->stiffness);
          m->set_damping(r->damping);
          m->set_effective_mass(r->mass);
          m->set_static_stiffness(r->static_stiffness);
          for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) m->add_compliance(r->compliance(i, j));
          }
          *m->mutable_velocity() = ToVec3(r->velocity);
          if (r->build_ms > 50) {
            SessionLog().info("probe {}: contact stiffness built in {:.0f} ms", s.channel->id(),
                              r->build_ms);
          }
        } else if (absl::IsUnavailable(r.status())) {
          contact_wanted_ = true;  // being built (or to be): sent without stiffness
        } else {
          SessionLog().warn("probe {}: no contact stiffness: {}", s.channel->id(),
                            r.status().ToString());
        }
        // The load that acted during the step that made this state.
        if (s.applied_at.has_value()) *m->mutable_applied_force() = ToVec3(s.applied);
        s.recent.push_back(*here);
        while (s.recent.size() > kRecentModels) s.recent.pop_front();
      }
      // The reaction: minus the reported coupling force, at the contact
      // point of the model it was rendered from (else the current one).
      const Eigen::Vector3d f = FromVec3(s.pose->coupling_force());
      std::optional<Sim::Located> at;
      if (fresh && f.squaredNorm() > 0) {
        for (auto it = s.recent.rbegin(); it != s.recent.rend(); ++it) {
          if (it->step == s.pose->model_step()) {
            at = *it;
            break;
          }
        }
        if (!at.has_value()) at = here;
      }
      if (at.has_value()) {
        loads.push_back({at->quad, at->u, at->v, -f});
        s.applied = -f;
        s.applied_at = at;
        pushed_ = true;
      } else {
        s.applied.setZero();
        s.applied_at.reset();
      }
    }
    s.channel->SetApplied(s.applied, 0);
    s.channel->Offer(std::move(reply));
  }
  if (!loads.empty() || loads_on_) {
    if (absl::Status st = solid.SetContactLoads(loads); !st.ok()) {
      SessionLog().warn("probe loads refused: {}", st.ToString());  // checked above: not expected
    }
    loads_on_ = solid.has_contact_loads();
  }
  if (sims_.empty() && pushed_ && !loads_on_) {
    result.contact_ended = true;
    pushed_ = false;
  }
  TendContactBuild(core);  // a build started if a probe wanted one
  result.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

void ProbeHub::FillStats(SessionStats* stats) const {
  std::vector<std::shared_ptr<ProbeChannel>> channels;
  int64_t total = 0;
  {
    absl::MutexLock lock(&mu_);
    channels = channels_;
    total = total_;
  }
  stats->set_probes(static_cast<int32_t>(channels.size()));
  stats->set_probes_total(total);
  for (const auto& c : channels) *stats->add_probe_details() = c->Stats();
}

}  // namespace dynsolid::server
