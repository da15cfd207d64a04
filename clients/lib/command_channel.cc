#include "clients/lib/command_channel.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"

namespace dynsolid::client {
namespace {

using Clock = std::chrono::steady_clock;

// Stream statuses after which reconnecting cannot help: the shared ones
// and FAILED_PRECONDITION.
bool Fatal(grpc::StatusCode code) {
  return IsFinalStreamStatus(code) || code == grpc::StatusCode::FAILED_PRECONDITION;
}


}  // namespace

CommandChannel::CommandChannel(ChannelFactory channels, SessionRef session,
                               std::string client_id, CommandChannelOptions options)
    : channels_(std::move(channels)),
      stub_(Sessions::NewStub(channels_())),
      session_(std::move(session)),
      client_id_(std::move(client_id)),
      options_(options) {
  reader_ = std::thread([this] { ReaderLoop(); });
}

CommandChannel::~CommandChannel() {
  {
    absl::MutexLock lock(&mu_);
    closing_ = true;
    done_ = true;
    if (stream_ != nullptr) stream_->context.TryCancel();
  }
  if (reader_.joinable()) reader_.join();
}

CommandRequest CommandChannel::RequestFor(const CommandRecord& r) const {
  CommandRequest request;
  // Every request names the session: a resend may open a stream.
  *request.mutable_session() = session_;
  request.set_client_id(client_id_);
  request.set_seq(r.seq);
  *request.mutable_command() = r.command;
  return request;
}

absl::StatusOr<uint64_t> CommandChannel::Send(const Command& command, std::string label) {
  absl::MutexLock write_lock(&write_mu_);
  std::shared_ptr<Stream> stream;
  CommandRequest request;
  uint64_t seq = 0;
  {
    absl::MutexLock lock(&mu_);
    if (!fatal_.ok()) return fatal_;
    if (closing_ || done_) return absl::FailedPreconditionError("the command channel is closed");
    seq = next_seq_++;
    CommandRecord& r = records_[seq];
    r.seq = seq;
    r.command = command;
    r.label = std::move(label);
    r.sent = Clock::now();
    ++unanswered_;
    request = RequestFor(r);
    stream = stream_;
    if (stream != nullptr) ++r.writes;
  }
  if (stream != nullptr) {
    // A failed write means the stream broke: the reader reconnects and
    // writes this command again.
    (void)stream->rw->Write(request);
    if (options_.break_every > 0 && seq % options_.break_every == 0) {
      stream->context.TryCancel();
    }
  }
  return seq;
}

std::shared_ptr<CommandChannel::Stream> CommandChannel::Open(bool fresh) {
  if (fresh) stub_ = Sessions::NewStub(channels_());
  auto s = std::make_shared<Stream>();
  absl::MutexLock write_lock(&write_mu_);
  s->rw = stub_->Commands(&s->context);
  std::vector<CommandRequest> pending;
  {
    absl::MutexLock lock(&mu_);
    if (done_) {
      s->context.TryCancel();
    }
    stream_ = s;
    for (auto& [seq, r] : records_) {
      if (r.answered) continue;
      pending.push_back(RequestFor(r));
      ++r.writes;
    }
  }
  for (const CommandRequest& request : pending) {
    if (!s->rw->Write(request)) break;
  }
  return s;
}

void CommandChannel::HandleReply(const CommandReply& reply) {
  absl::MutexLock lock(&mu_);
  auto it = records_.find(reply.seq());
  if (reply.client_id() != client_id_ || it == records_.end() || it->second.answered) {
    ++extra_answers_;
    if (it != records_.end()) ++it->second.answers;
    return;
  }
  CommandRecord& r = it->second;
  r.answered = true;
  r.answers = 1;
  r.reply = reply;
  r.latency_ms = std::chrono::duration<double, std::milli>(Clock::now() - r.sent).count();
  --unanswered_;
}

void CommandChannel::ReaderLoop() {
  Clock::time_point broken_since{};
  bool broken = false;
  int backoff_ms = 50;
  int redirects = 0;  // in a row, without a reply in between
  for (;;) {
    {
      absl::MutexLock lock(&mu_);
      if (done_ || (closing_ && unanswered_ == 0)) break;
    }
    std::shared_ptr<Stream> s = Open(/*fresh=*/broken);
    const Clock::time_point opened = Clock::now();
    CommandReply reply;
    bool got_reply = false;
    while (s->rw->Read(&reply)) {
      got_reply = true;
      if (reply.code() == static_cast<int>(grpc::StatusCode::RESOURCE_EXHAUSTED) &&
          reply.applied_step() == -1) {
        // Rate limited: never considered; send it again a little later.
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        absl::MutexLock write_lock(&write_mu_);
        CommandRequest again;
        {
          absl::MutexLock lock(&mu_);
          auto it = records_.find(reply.seq());
          if (it == records_.end() || it->second.answered) continue;
          ++it->second.rate_limited;
          ++it->second.writes;
          again = RequestFor(it->second);
        }
        (void)s->rw->Write(again);
        continue;
      }
      HandleReply(reply);
    }
    grpc::Status status;
    {
      absl::MutexLock write_lock(&write_mu_);
      {
        absl::MutexLock lock(&mu_);
        if (stream_ == s) stream_.reset();
      }
      status = s->rw->Finish();
    }
    absl::MutexLock lock(&mu_);
    if (done_ || (closing_ && unanswered_ == 0)) break;
    if (got_reply) redirects = 0;
    if (redirects < kMaxRedirects && channels_.Follow(status)) {
      // The session lives on another replica: open the stream there now
      // and resend what is unanswered (same seqs: exactly once still).
      ++redirects;
      broken = true;
      broken_since = Clock::now();
      if (options_.log) options_.log(absl::StrCat("commands: ", status.error_message()));
      continue;
    }
    if (Fatal(status.error_code())) {
      fatal_ = ToAbslStatus(status);
      done_ = true;
      break;
    }
    // Broken (UNAVAILABLE, CANCELLED by fault injection, ...): reconnect.
    const Clock::time_point now = Clock::now();
    if (got_reply || now - opened > std::chrono::seconds(1)) {
      broken = false;
      backoff_ms = 50;
    }
    if (!broken) {
      broken = true;
      broken_since = now;
    }
    if (now - broken_since > absl::ToChronoNanoseconds(options_.reconnect_timeout)) {
      fatal_ = absl::UnavailableError(absl::StrCat(
          "no working Commands stream for ", absl::FormatDuration(options_.reconnect_timeout),
          " (last: ", status.error_message(), ")"));
      done_ = true;
      break;
    }
    ++reconnects_;
    if (options_.log) {
      options_.log(absl::StrCat("commands: stream ended (", status.error_code(), " ",
                                status.error_message(), "); reconnect ", reconnects_, " with ",
                                unanswered_, " unanswered"));
    }
    // Sleep outside the lock, but wake early when closing.
    const absl::Duration wait = absl::Milliseconds(backoff_ms);
    backoff_ms = std::min(backoff_ms * 2, 1000);
    mu_.AwaitWithTimeout(absl::Condition(
                             +[](CommandChannel* c) ABSL_EXCLUSIVE_LOCKS_REQUIRED(c->mu_) {
                               return c->done_;
                             },
                             this),
                         wait);
  }
}

absl::StatusOr<CommandReply> CommandChannel::Wait(uint64_t seq, absl::Duration timeout) {
  absl::MutexLock lock(&mu_);
  auto answered_or_dead = [this, seq]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    auto it = records_.find(seq);
    return done_ || it == records_.end() || it->second.answered;
  };
  mu_.AwaitWithTimeout(absl::Condition(&answered_or_dead), timeout);
  auto it = records_.find(seq);
  if (it == records_.end()) return absl::NotFoundError(absl::StrCat("no command seq ", seq));
  if (it->second.answered) return it->second.reply;
  if (!fatal_.ok()) return fatal_;
  if (done_) return absl::CancelledError("the command channel was closed");
  return absl::DeadlineExceededError(absl::StrCat("no answer to command seq ", seq, " (",
                                                  it->second.label, ") within ",
                                                  absl::FormatDuration(timeout)));
}

absl::Status CommandChannel::WaitAll(absl::Duration timeout) {
  absl::MutexLock lock(&mu_);
  auto all = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return done_ || unanswered_ == 0; };
  mu_.AwaitWithTimeout(absl::Condition(&all), timeout);
  if (unanswered_ == 0) return absl::OkStatus();
  if (!fatal_.ok()) return fatal_;
  return absl::DeadlineExceededError(absl::StrCat(unanswered_, " commands unanswered after ",
                                                  absl::FormatDuration(timeout)));
}

absl::Status CommandChannel::Close(absl::Duration timeout) {
  absl::Status result = WaitAll(timeout);
  {
    absl::MutexLock write_lock(&write_mu_);
    absl::MutexLock lock(&mu_);
    closing_ = true;
    if (stream_ != nullptr) {
      if (result.ok()) {
        (void)stream_->rw->WritesDone();
      } else {
        stream_->context.TryCancel();
      }
    }
  }
  // The reader ends when the server finishes the half-closed stream.
  {
    absl::MutexLock lock(&mu_);
    auto finished = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
      return done_ || stream_ == nullptr;
    };
    if (!mu_.AwaitWithTimeout(absl::Condition(&finished), absl::Seconds(10))) {
      if (stream_ != nullptr) stream_->context.TryCancel();
    }
    done_ = true;
  }
  if (reader_.joinable()) reader_.join();
  return result;
}

std::vector<CommandRecord> CommandChannel::Records() const {
  absl::MutexLock lock(&mu_);
  std::vector<CommandRecord> out;
  out.reserve(records_.size());
  for (const auto& [seq, r] : records_) out.push_back(r);
  return out;
}

int CommandChannel::reconnects() const {
  absl::MutexLock lock(&mu_);
  return reconnects_;
}

int64_t CommandChannel::extra_answers() const {
  absl::MutexLock lock(&mu_);
  return extra_answers_;
}

}  // namespace dynsolid::client
