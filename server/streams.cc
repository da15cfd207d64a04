#include "server/streams.h"

#include <deque>
#include <string>
#include <utility>

#include <grpcpp/impl/codegen/proto_utils.h>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "server/grpc_status.h"
#include "server/log.h"
#include "server/session_loop.h"
#include "server/sim_core.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::server {
namespace {

// ---------------------------------------------------------------- Watch

// Frees the reference a frame's slice holds on its shared bytes.
void ReleaseBytes(void* holder) {
  delete static_cast<std::shared_ptr<const std::string>*>(holder);
}

class WatchState final : public WatchSink, public std::enable_shared_from_this<WatchState> {
 public:
  WatchState(grpc::ServerWriteReactor<grpc::ByteBuffer>* reactor, WorkQueue& encoders,
             FieldChoice fields, double rate_hz, std::string client_id,
             std::shared_ptr<EncodeCache> cache)
      : reactor_(reactor), encoders_(encoders), fields_(fields), rate_hz_(rate_hz),
        client_id_(std::move(client_id)),
        encoder_(fields, std::move(cache)) {}

  void set_watcher_id(int64_t id) override {
    absl::MutexLock lock(&mu_);
    id_ = id;
  }

  void Offer(std::shared_ptr<const SurfaceSnapshot> snapshot) override {
    bool post = false;
    {
      absl::MutexLock lock(&mu_);
      if (done_) return;
      if (slot_ != nullptr) {
        ++skipped_since_;
        ++frames_skipped_;
      }
      slot_ = std::move(snapshot);
      if (!busy_) {
        busy_ = true;
        post = true;
      }
    }
    if (post) Post();
  }

  void Stop(const absl::Status& status) override { End(status); }
  void OnCancel() { End(absl::CancelledError("the client cancelled the watch")); }

  void OnWriteDone(bool ok) {
    bool post = false;
    bool finish = false;
    grpc::Status status;
    {
      absl::MutexLock lock(&mu_);
      write_pending_ = false;
      if (ok) {
        ++frames_sent_;
        bytes_sent_ += pending_bytes_;
        if (pending_key_) ++keyframes_sent_;
        last_step_ = pending_step_;
      } else if (!done_) {
        done_ = true;
        status_ = absl::UnavailableError("the watch stream broke");
      }
      if (!done_ && slot_ != nullptr) {
        post = true;  // busy_ stays set: the next encode owns the encoder
      } else {
        busy_ = false;
        finish = TakeFinishLocked(&status);
      }
    }
    if (post) Post();
    if (finish) reactor_->Finish(status);
  }

  WatcherStats Stats() const override {
    absl::MutexLock lock(&mu_);
    WatcherStats w;
    w.set_watcher_id(id_);
    w.set_rate_hz(rate_hz_);
    w.set_frames_sent(frames_sent_);
    w.set_keyframes_sent(keyframes_sent_);
    w.set_frames_skipped(frames_skipped_);
    w.set_bytes_sent(bytes_sent_);
    w.set_write_pending(write_pending_);
    w.set_last_step(last_step_);
    return w;
  }
  const FieldChoice& fields() const override { return fields_; }
  double rate_hz() const override { return rate_hz_; }
  const std::string& client_id() const override { return client_id_; }

 private:
  void Post() {
    encoders_.Post([self = shared_from_this()](bool run) { self->EncodeAndWrite(run); });
  }

  void End(const absl::Status& status) {
    bool finish = false;
    grpc::Status g;
    {
      absl::MutexLock lock(&mu_);
      if (!done_) {
        done_ = true;
        status_ = status;
      }
      slot_.reset();
      finish = !busy_ && TakeFinishLocked(&g);
    }
    if (finish) reactor_->Finish(g);
  }

  bool TakeFinishLocked(grpc::Status* status) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    if (!done_ || finished_) return false;
    finished_ = true;
    *status = ToGrpcStatus(status_);
    return true;
  }

  void EncodeAndWrite(bool run) {
    std::shared_ptr<const SurfaceSnapshot> snap;
    int64_t skipped = 0;
    int64_t id = 0;
    bool finish = false;
    grpc::Status g;
    {
      absl::MutexLock lock(&mu_);
      if (!run && !done_) {
        done_ = true;
        status_ = absl::UnavailableError("the server is shutting down");
      }
      if (done_ || slot_ == nullptr) {
        busy_ = false;
        finish = TakeFinishLocked(&g);
      } else {
        snap = std::move(slot_);
        skipped = skipped_since_;
        skipped_since_ = 0;
        id = id_;
      }
    }
    if (snap == nullptr) {
      if (finish) reactor_->Finish(g);
      return;
    }
    // Only the holder of busy_ touches the encoder and buffer_. The frame
    // body is serialized once per state (EncodeCache) and shared by
    // reference; this watcher's own fields follow it (FrameTrailer).
    std::shared_ptr<const EncodeCache::Result> r = encoder_.EncodeShared(snap);
    const std::string trailer = FrameTrailer(skipped, id);
    const std::string& body = *r->bytes;
    grpc::Slice slices[2] = {
        grpc::Slice(const_cast<char*>(body.data()), body.size(), &ReleaseBytes,
                    new std::shared_ptr<const std::string>(r->bytes)),
        grpc::Slice(trailer)};
    buffer_ = grpc::ByteBuffer(slices, trailer.empty() ? 1 : 2);
    {
      absl::MutexLock lock(&mu_);
      pending_key_ = r->keyframe;
      pending_bytes_ = static_cast<int64_t>(body.size() + trailer.size());
      pending_step_ = snap->step;
      write_pending_ = true;
    }
    reactor_->StartWrite(&buffer_);
  }

  grpc::ServerWriteReactor<grpc::ByteBuffer>* const reactor_;
  WorkQueue& encoders_;
  const FieldChoice fields_;
  const double rate_hz_;
  const std::string client_id_;
  SurfaceEncoder encoder_;
  grpc::ByteBuffer buffer_;  // the write in flight

  mutable absl::Mutex mu_;
  int64_t id_ ABSL_GUARDED_BY(mu_) = 0;
  std::shared_ptr<const SurfaceSnapshot> slot_ ABSL_GUARDED_BY(mu_);
  bool busy_ ABSL_GUARDED_BY(mu_) = false;      // an encode is queued or a write in flight
  bool done_ ABSL_GUARDED_BY(mu_) = false;      // finish once not busy
  bool finished_ ABSL_GUARDED_BY(mu_) = false;  // Finish called
  absl::Status status_ ABSL_GUARDED_BY(mu_);
  int64_t skipped_since_ ABSL_GUARDED_BY(mu_) = 0;
  bool write_pending_ ABSL_GUARDED_BY(mu_) = false;
  bool pending_key_ ABSL_GUARDED_BY(mu_) = false;
  int64_t pending_bytes_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t pending_step_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t frames_sent_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t keyframes_sent_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t frames_skipped_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t bytes_sent_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t last_step_ ABSL_GUARDED_BY(mu_) = -1;
};

class WatchReactor final : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  WatchReactor(const grpc::ByteBuffer& raw, SessionRegistry& registry, WorkQueue& encoders,
               const StreamOptions& options) {
    // The method is registered raw (frames go out as shared bytes), so the
    // request is parsed here.
    WatchRequest request;
    grpc::ByteBuffer copy(raw);
    absl::Status s = grpc::SerializationTraits<WatchRequest>::Deserialize(&copy, &request).ok()
                         ? scene::ValidateValues(request, "")
                         : absl::InvalidArgumentError("WatchRequest: not a valid message");
    double rate = request.rate_hz();
    if (s.ok() && (rate < 0 || rate > options.max_watch_hz)) {
      s = absl::InvalidArgumentError(absl::StrCat("rate_hz: must be in (0, ", options.max_watch_hz,
                                                  "] or 0 for the default, got ", rate));
    }
    if (s.ok()) s = CheckClientIdCharacters(request.client_id());
    if (rate == 0) rate = options.watch_hz;
    absl::StatusOr<std::shared_ptr<const SolidSession>> session =
        s.ok() ? registry.Get(request.session().id(), request.session().token())
               : absl::StatusOr<std::shared_ptr<const SolidSession>>(s);
    if (!session.ok()) {
      Finish(ToGrpcStatus(session.status()));
      return;
    }
    session_ = *std::move(session);
    FieldChoice fields{request.displacement(), request.strain(), request.stiffness(),
                       request.mass()};
    state_ = std::make_shared<WatchState>(this, encoders, fields, rate, request.client_id(),
                                          session_->loop().encode_cache());
    absl::StatusOr<int64_t> id = session_->loop().AddWatcher(state_);
    if (!id.ok()) {
      state_.reset();
      Finish(ToGrpcStatus(id.status()));
      return;
    }
    WatchLog().info("session {}: watcher {} joined at {:.0f} Hz", session_->id(), *id, rate);
  }

  void OnWriteDone(bool ok) override { state_->OnWriteDone(ok); }
  void OnCancel() override {
    if (state_ != nullptr) state_->OnCancel();
  }
  void OnDone() override {
    if (state_ != nullptr) {
      const WatcherStats w = state_->Stats();
      WatchLog().info("session {}: watcher {} left after {} frames ({} keyframes, {} bytes), {} "
                      "skipped",
                      session_->id(), w.watcher_id(), w.frames_sent(), w.keyframes_sent(),
                      w.bytes_sent(), w.frames_skipped());
      session_->loop().RemoveWatcher(state_.get());
    }
    delete this;
  }

 private:
  std::shared_ptr<const SolidSession> session_;
  std::shared_ptr<WatchState> state_;
};

// ------------------------------------------------------------- Commands

class CommandsReactor;

class CommandsState final : public ReplySink {
 public:
  explicit CommandsState(grpc::ServerBidiReactor<Parsed<CommandRequest>, CommandReply>* reactor)
      : reactor_(reactor) {}

  // A reply from the session loop (after it is durable).
  void Reply(const CommandReply& reply) override { Enqueue(reply, /*from_loop=*/true); }
  // A reply made on arrival (rate limited, bad envelope).
  void ReplyNow(const CommandReply& reply) { Enqueue(reply, /*from_loop=*/false); }

  void Stop(const absl::Status& status) override {
    grpc::Status g;
    bool finish = false;
    {
      absl::MutexLock lock(&mu_);
      if (!done_) {
        done_ = true;
        status_ = status;
      }
      out_.clear();
      finish = TakeFinishLocked(&g);
    }
    if (finish) reactor_->Finish(g);
  }

  void Submitted() {
    absl::MutexLock lock(&mu_);
    ++outstanding_;
  }
  // The client half-closed (or the stream broke).
  void ReadsDone() {
    grpc::Status g;
    bool finish = false;
    {
      absl::MutexLock lock(&mu_);
      reads_done_ = true;
      finish = TakeFinishLocked(&g);
    }
    if (finish) reactor_->Finish(g);
  }
  bool finished() const {
    absl::MutexLock lock(&mu_);
    return finished_ || done_;
  }

  void OnWriteDone(bool ok) {
    grpc::Status g;
    bool finish = false;
    bool write = false;
    {
      absl::MutexLock lock(&mu_);
      writing_ = false;
      if (!ok && !done_) {
        done_ = true;
        status_ = absl::UnavailableError("the command stream broke");
      }
      if (!done_ && !out_.empty()) {
        current_ = std::move(out_.front());
        out_.pop_front();
        writing_ = true;
        write = true;
      } else {
        finish = TakeFinishLocked(&g);
      }
    }
    if (write) reactor_->StartWrite(&current_);
    if (finish) reactor_->Finish(g);
  }

 private:
  void Enqueue(const CommandReply& reply, bool from_loop) {
    bool write = false;
    bool finish = false;
    grpc::Status g;
    {
      absl::MutexLock lock(&mu_);
      if (from_loop) --outstanding_;
      if (done_) return;
      if (out_.size() >= kMaxQueuedReplies) {
        // A client that sends but does not read: no unbounded queue.
        done_ = true;
        status_ = absl::ResourceExhaustedError(absl::StrCat(
            kMaxQueuedReplies, " replies are waiting for the client to read them"));
        out_.clear();
        finish = TakeFinishLocked(&g);
      } else {
        out_.push_back(reply);
      }
      if (!done_ && !writing_) {
        current_ = std::move(out_.front());
        out_.pop_front();
        writing_ = true;
        write = true;
      }
    }
    if (write) reactor_->StartWrite(&current_);
    if (finish) reactor_->Finish(g);
  }

  static constexpr size_t kMaxQueuedReplies = 4096;

  // Finish when ended (stopped, broken) or when the client half-closed and
  // every reply is written; never with a write in flight.
  bool TakeFinishLocked(grpc::Status* g) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    if (finished_ || writing_) return false;
    if (done_) {
      *g = ToGrpcStatus(status_);
    } else if (reads_done_ && outstanding_ == 0 && out_.empty()) {
      *g = grpc::Status::OK;
    } else {
      return false;
    }
    finished_ = true;
    return true;
  }

  grpc::ServerBidiReactor<Parsed<CommandRequest>, CommandReply>* const reactor_;
  mutable absl::Mutex mu_;
  std::deque<CommandReply> out_ ABSL_GUARDED_BY(mu_);
  CommandReply current_;  // the write in flight
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  bool reads_done_ ABSL_GUARDED_BY(mu_) = false;
  int64_t outstanding_ ABSL_GUARDED_BY(mu_) = 0;
  bool done_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status status_ ABSL_GUARDED_BY(mu_);
};

class CommandsReactor final : public grpc::ServerBidiReactor<Parsed<CommandRequest>, CommandReply> {
 public:
  CommandsReactor(grpc::CallbackServerContext* context, SessionRegistry& registry)
      : context_(context), registry_(registry), state_(std::make_shared<CommandsState>(this)) {
    StartRead(&read_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      state_->ReadsDone();
      return;
    }
    if (state_->finished()) return;
    // Bytes that are not a CommandRequest end the stream (gRPC's own
    // handler would end the reads as if the client had half-closed).
    if (absl::Status s = read_.parsed ? Handle() : NotAMessage(read_); !s.ok()) {
      state_->Stop(s);
      return;
    }
    StartRead(&read_);
  }
  void OnWriteDone(bool ok) override { state_->OnWriteDone(ok); }
  void OnCancel() override { state_->Stop(absl::CancelledError("the client cancelled")); }
  void OnDone() override {
    if (session_ != nullptr) session_->loop().UnregisterCommandStream(state_.get());
    delete this;
  }

 private:
  // Authorizes (first request), checks the envelope and the rate, submits.
  // An error ends the stream.
  absl::Status Handle() {
    if (session_ == nullptr) {
      if (!request_.has_session()) {
        return absl::InvalidArgumentError(
            "session: required in the first CommandRequest of a stream");
      }
      absl::StatusOr<std::shared_ptr<const SolidSession>> s =
          registry_.Get(request_.session().id(), request_.session().token());
      if (!s.ok()) return s.status();
      session_ = *std::move(s);
      if (absl::Status r = session_->loop().RegisterCommandStream(state_); !r.ok()) {
        session_.reset();
        return r;
      }
      SessionLog().info("session {}: command stream from {}", session_->id(), context_->peer());
    } else if (request_.has_session()) {
      if (request_.session().id() != session_->id()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "session.id: this stream is for session ", session_->id(), ", got \"",
            request_.session().id(), "\""));
      }
      if (!session_->TokenMatches(request_.session().token())) {
        return absl::PermissionDeniedError(
            absl::StrCat("SessionRef.token does not match session ", session_->id()));
      }
    }
    SessionLoop& loop = session_->loop();
    if (absl::Status s = CheckCommandEnvelope(request_); !s.ok()) {
      state_->ReplyNow(Refusal(s));
      return absl::OkStatus();
    }
    if (!loop.AllowCommand(request_.client_id(), request_.seq())) {
      loop.CountRateLimited();
      state_->ReplyNow(Refusal(absl::ResourceExhaustedError(absl::StrCat(
          "client ", request_.client_id(),
          " sends commands faster than this server allows (--max_commands_per_second); "
          "send seq ", request_.seq(), " again later"))));
      return absl::OkStatus();
    }
    state_->Submitted();
    loop.Submit(request_, state_);
    return absl::OkStatus();
  }

  CommandReply Refusal(const absl::Status& s) const {
    CommandReply r;
    r.set_client_id(request_.client_id());
    r.set_seq(request_.seq());
    r.set_code(static_cast<int32_t>(s.code()));
    r.set_message(std::string(s.message()));
    r.set_applied_step(-1);
    return r;
  }

  grpc::CallbackServerContext* const context_;
  SessionRegistry& registry_;
  std::shared_ptr<CommandsState> state_;
  std::shared_ptr<const SolidSession> session_;
  Parsed<CommandRequest> read_;
  CommandRequest& request_ = read_.message;
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* StartWatch(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request,
                                                       SessionRegistry& registry,
                                                       WorkQueue& encoders,
                                                       const StreamOptions& options) {
  (void)context;
  return new WatchReactor(*request, registry, encoders, options);
}

grpc::ServerBidiReactor<Parsed<CommandRequest>, CommandReply>* StartCommands(
    grpc::CallbackServerContext* context, SessionRegistry& registry) {
  return new CommandsReactor(context, registry);
}

}  // namespace dynsolid::server
