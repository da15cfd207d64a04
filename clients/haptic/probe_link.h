// The bridge's side of the Probe stream (service.proto rpc Probe), kept
// out of the 1 kHz loop: a writer thread sends the newest pose the loop
// posted, a reader thread keeps the newest contact model; the loop only
// exchanges them through short try-locks (a busy lock costs it one tick's
// freshness, never a wait). When the stream breaks the link reports down
// at once (the loop ramps its force to zero) and reconnects by itself on
// a new channel, backing off from 50 ms to 1 s; statuses after which
// reconnecting cannot help (wrong token, no such session) are final.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/synchronization/mutex.h"
#include "clients/lib/channel.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::haptic {

struct ProbeLinkOptions {
  client::ChannelFactory channels;
  SessionRef session;
  ProbeOptions options;
  client::LogFn log;  // reconnects and refusals; may be empty
};

class ProbeLink {
 public:
  explicit ProbeLink(ProbeLinkOptions options);
  ~ProbeLink();  // Stop()
  ProbeLink(const ProbeLink&) = delete;
  ProbeLink& operator=(const ProbeLink&) = delete;

  void Start();
  // Half-closes the stream and joins the threads.
  void Stop();

  // ---- The loop's side (never blocks).
  // The newest pose to send (replaces one not yet written). False when
  // the lock was busy (post again next tick).
  bool PostPose(const ProbePose& pose);
  // The newest model not taken yet (copied into *model, reusing its
  // storage), with its arrival time (steady clock). False when there is
  // none (or the lock was busy).
  bool TakeModel(ContactModel* model, std::chrono::steady_clock::time_point* arrival);
  // A stream is open (it broke: false until the next one is).
  bool up() const { return up_.load(std::memory_order_acquire); }
  // Reconnecting stopped for good (Counters::final_status says why).
  bool failed() const { return failed_.load(std::memory_order_acquire); }

  struct Counters {
    int64_t replies = 0, models = 0, poses_sent = 0, rejected = 0, reconnects = 0,
            streams_opened = 0;
    std::string last_rejection;
    absl::Status final_status;  // set when reconnecting stopped
  };
  Counters counters() const;
  // Round trips: from writing pose seq to receiving the first model made
  // for it (seconds), the newest ones (the loop reads them at exit).
  std::vector<double> round_trips() const;

 private:
  struct Stream {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<ProbeRequest, ProbeReply>> rw;
  };
  void ReaderLoop();  // connects, reads, reconnects
  void WriterLoop();

  const ProbeLinkOptions options_;
  std::atomic<bool> up_{false};
  std::atomic<bool> failed_{false};

  mutable absl::Mutex mu_;
  absl::CondVar pose_ready_;
  // The pose and model slots stay allocated (a flag says whether they
  // hold something new), so the loop's copies reuse their storage: the
  // loop neither allocates nor frees.
  ProbePose pose_ ABSL_GUARDED_BY(mu_);
  bool has_pose_ ABSL_GUARDED_BY(mu_) = false;
  std::shared_ptr<Stream> stream_ ABSL_GUARDED_BY(mu_);
  bool first_written_ ABSL_GUARDED_BY(mu_) = false;  // the session/options request
  ContactModel model_ ABSL_GUARDED_BY(mu_);
  bool has_model_ ABSL_GUARDED_BY(mu_) = false;
  std::chrono::steady_clock::time_point model_arrival_ ABSL_GUARDED_BY(mu_);
  bool stop_ ABSL_GUARDED_BY(mu_) = false;
  Counters counters_ ABSL_GUARDED_BY(mu_);
  // Sent poses (seq, when) awaiting their first model.
  std::deque<std::pair<uint64_t, std::chrono::steady_clock::time_point>> sent_ ABSL_GUARDED_BY(mu_);
  std::vector<double> round_trips_ ABSL_GUARDED_BY(mu_);
  std::thread reader_, writer_;
};

}  // namespace dynsolid::haptic
