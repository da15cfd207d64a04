#include "clients/haptic/probe_link.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/time/time.h"

namespace dynsolid::haptic {
namespace {

using Clock = std::chrono::steady_clock;
constexpr size_t kMaxRoundTrips = 1 << 20;
constexpr size_t kMaxPending = 4096;

}  // namespace

ProbeLink::ProbeLink(ProbeLinkOptions options) : options_(std::move(options)) {}

ProbeLink::~ProbeLink() { Stop(); }

void ProbeLink::Start() {
  reader_ = std::thread([this] { ReaderLoop(); });
  writer_ = std::thread([this] { WriterLoop(); });
}

void ProbeLink::Stop() {
  std::shared_ptr<Stream> s;
  {
    absl::MutexLock lock(&mu_);
    if (stop_ && !reader_.joinable() && !writer_.joinable()) return;
    stop_ = true;
    s = stream_;
    pose_ready_.SignalAll();
  }
  if (s != nullptr) s->context.TryCancel();
  if (writer_.joinable()) writer_.join();
  if (reader_.joinable()) reader_.join();
}

bool ProbeLink::PostPose(const ProbePose& pose) {
  if (!mu_.TryLock()) return false;
  pose_.CopyFrom(pose);
  has_pose_ = true;
  pose_ready_.Signal();
  mu_.Unlock();
  return true;
}

bool ProbeLink::TakeModel(ContactModel* model, Clock::time_point* arrival) {
  if (!mu_.TryLock()) return false;
  bool got = false;
  if (has_model_) {
    model->CopyFrom(model_);
    *arrival = model_arrival_;
    has_model_ = false;
    got = true;
  }
  mu_.Unlock();
  return got;
}

ProbeLink::Counters ProbeLink::counters() const {
  absl::MutexLock lock(&mu_);
  return counters_;
}

std::vector<double> ProbeLink::round_trips() const {
  absl::MutexLock lock(&mu_);
  return round_trips_;
}

void ProbeLink::WriterLoop() {
  for (;;) {
    ProbePose pose;
    std::shared_ptr<Stream> s;
    {
      absl::MutexLock lock(&mu_);
      while (!stop_ && !(has_pose_ && stream_ != nullptr && first_written_)) {
        pose_ready_.Wait(&mu_);
      }
      if (stop_) return;
      pose.CopyFrom(pose_);
      has_pose_ = false;
      s = stream_;
    }
    ProbeRequest request;
    *request.mutable_pose() = pose;
    const bool ok = s->rw->Write(request);
    absl::MutexLock lock(&mu_);
    if (ok) {
      ++counters_.poses_sent;
      if (sent_.size() < kMaxPending) sent_.emplace_back(pose.seq(), Clock::now());
    } else if (stream_ == s) {
      // The stream is broken; the reader notices and replaces it.
      stream_.reset();
    }
  }
}

void ProbeLink::ReaderLoop() {
  auto backoff = std::chrono::milliseconds(50);
  bool opened_before = false;
  int redirects = 0;  // in a row, without a delivered pose in between
  for (;;) {
    {
      absl::MutexLock lock(&mu_);
      if (stop_) return;
    }
    auto s = std::make_shared<Stream>();
    std::unique_ptr<Sessions::Stub> stub = Sessions::NewStub(options_.channels());
    s->rw = stub->Probe(&s->context);
    ProbeRequest first;
    *first.mutable_session() = options_.session;
    *first.mutable_options() = options_.options;
    bool delivered = false;
    if (s->rw->Write(first)) {
      {
        absl::MutexLock lock(&mu_);
        if (stop_) {
          s->context.TryCancel();
        } else {
          stream_ = s;
          first_written_ = true;
          sent_.clear();
          ++counters_.streams_opened;
          if (opened_before) ++counters_.reconnects;
          pose_ready_.SignalAll();
        }
      }
      opened_before = true;
      ProbeReply reply;
      while (s->rw->Read(&reply)) {
        const Clock::time_point now = Clock::now();
        if (!delivered) {
          delivered = true;
          up_.store(true, std::memory_order_release);
          if (options_.log) options_.log("probe stream open");
        }
        absl::MutexLock lock(&mu_);
        ++counters_.replies;
        counters_.rejected = reply.rejected_total();
        if (reply.rejected_size() > 0) {
          const PoseRejection& r = reply.rejected(reply.rejected_size() - 1);
          counters_.last_rejection = absl::StrCat("pose ", r.seq(), ": ", r.message());
        }
        if (reply.has_model()) {
          ++counters_.models;
          const uint64_t seq = reply.model().pose_seq();
          while (!sent_.empty() && sent_.front().first < seq) sent_.pop_front();
          if (!sent_.empty() && sent_.front().first == seq) {
            if (round_trips_.size() < kMaxRoundTrips) {
              round_trips_.push_back(
                  std::chrono::duration<double>(now - sent_.front().second).count());
            }
            sent_.pop_front();
          }
          model_.Swap(reply.mutable_model());
          has_model_ = true;
          model_arrival_ = now;
        }
      }
    }
    up_.store(false, std::memory_order_release);
    {
      absl::MutexLock lock(&mu_);
      if (stream_ == s) stream_.reset();
      first_written_ = false;
    }
    // The writer may still be in a Write on this stream; Finish waits for
    // the call's operations. The stream has ended (Read failed), so that
    // Write fails soon: let it leave, and Finish reads the server's status
    // (a redirect names the owner). Only a Write that stays stuck is
    // cancelled (the status is then CANCELLED).
    for (int i = 0; i < 1000; ++i) {
      if (s.use_count() <= 1) break;
      if (i == 100) s->context.TryCancel();
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    const grpc::Status status = s->rw->Finish();
    if (delivered) redirects = 0;
    if (redirects < client::kMaxRedirects && options_.channels.Follow(status)) {
      ++redirects;  // the session lives on another replica: probe it there
      if (options_.log) options_.log(absl::StrCat("probe: ", status.error_message()));
      continue;
    }
    bool stop = false;
    {
      absl::MutexLock lock(&mu_);
      stop = stop_;
      if (!stop && client::IsFinalStreamStatus(status.error_code())) {
        counters_.final_status = client::ToAbslStatus(status, "Probe");
        failed_.store(true, std::memory_order_release);
        stop = true;
      }
    }
    if (stop) {
      if (options_.log && !status.ok() && status.error_code() != grpc::StatusCode::CANCELLED) {
        options_.log(absl::StrCat("probe stream ended: ", status.error_message()));
      }
      return;
    }
    if (options_.log) {
      options_.log(absl::StrCat("probe stream broke (", static_cast<int>(status.error_code()), " ",
                                status.error_message(), "); reconnecting in ", backoff.count(),
                                " ms"));
    }
    if (delivered) backoff = std::chrono::milliseconds(50);
    {
      absl::MutexLock lock(&mu_);
      mu_.AwaitWithTimeout(absl::Condition(&stop_), absl::FromChrono(backoff));
      if (stop_) return;
    }
    backoff = std::min<std::chrono::milliseconds>(2 * backoff, std::chrono::seconds(1));
  }
}

}  // namespace dynsolid::haptic
