// A Commands stream that survives broken connections: every command gets a
// (client_id, seq); commands not yet answered are kept and written again,
// in seq order, on a new stream after the old one broke. The server answers
// each (client_id, seq) exactly once (a resend of an answered command gets
// the original answer with `duplicate` set), so every command is applied at
// most once and acknowledged once here.
//
// Thread-safety: Send, Wait, WaitAll, Close, Break and Records may be
// called from any thread; one background thread reads replies and
// reconnects.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"
#include "clients/lib/channel.h"
#include "dynsolid/service.grpc.pb.h"

namespace dynsolid::client {

struct CommandChannelOptions {
  // Stop reconnecting after this long without a working stream.
  absl::Duration reconnect_timeout = absl::Seconds(30);
  // Fault injection for tests: cancel the stream right after writing every
  // n-th command (0: never), before its reply is read, as a broken network
  // would; the channel then reconnects and resends.
  int break_every = 0;
  // Progress messages (reconnects); may be empty.
  LogFn log;
};

// One command's life.
struct CommandRecord {
  uint64_t seq = 0;
  Command command;
  // The caller's label (the script's "file:line").
  std::string label;
  // Writes of this command (1 + resends).
  int writes = 0;
  // Answered (code/applied_step/... are the answer).
  bool answered = false;
  CommandReply reply;
  // Answers received for it (1 when answered; more would be a server fault,
  // counted, not applied).
  int answers = 0;
  // Rate-limited answers (RESOURCE_EXHAUSTED, applied_step -1) that made the
  // channel send it again.
  int rate_limited = 0;
  std::chrono::steady_clock::time_point sent;
  double latency_ms = 0;  // first write to the answer
};

class CommandChannel {
 public:
  // `channels` makes the channel of each stream (a new one per reconnect).
  CommandChannel(ChannelFactory channels, SessionRef session,
                 std::string client_id, CommandChannelOptions options = {});
  ~CommandChannel();
  CommandChannel(const CommandChannel&) = delete;
  CommandChannel& operator=(const CommandChannel&) = delete;

  // Sends `command` (the next seq); returns its seq. Never waits for the
  // reply. Fails only after Close or a fatal stream error.
  absl::StatusOr<uint64_t> Send(const Command& command, std::string label);

  // Waits for the answer to `seq`. DeadlineExceeded after `timeout`; the
  // stream's fatal error (PERMISSION_DENIED, ...) if it died.
  absl::StatusOr<CommandReply> Wait(uint64_t seq, absl::Duration timeout);
  // Waits until every command sent is answered.
  absl::Status WaitAll(absl::Duration timeout);

  // Half-closes the stream after every answer is in and stops the reader.
  absl::Status Close(absl::Duration timeout);

  // Every command sent, in seq order.
  std::vector<CommandRecord> Records() const;
  int reconnects() const;
  // Answers to already answered seqs (should stay 0).
  int64_t extra_answers() const;

 private:
  struct Stream {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<CommandRequest, CommandReply>> rw;
  };
  void ReaderLoop();
  // Opens a stream and writes every unanswered command (under write_mu_);
  // `fresh`: on a new channel.
  std::shared_ptr<Stream> Open(bool fresh);
  CommandRequest RequestFor(const CommandRecord& r) const;
  void HandleReply(const CommandReply& reply);

  const ChannelFactory channels_;
  std::unique_ptr<Sessions::Stub> stub_;  // used by the reader thread only
  const SessionRef session_;
  const std::string client_id_;
  const CommandChannelOptions options_;

  // Orders writes: Send and the resends of a new stream.
  absl::Mutex write_mu_ ABSL_ACQUIRED_BEFORE(mu_);
  mutable absl::Mutex mu_;
  std::map<uint64_t, CommandRecord> records_ ABSL_GUARDED_BY(mu_);
  uint64_t next_seq_ ABSL_GUARDED_BY(mu_) = 1;
  int64_t unanswered_ ABSL_GUARDED_BY(mu_) = 0;
  std::shared_ptr<Stream> stream_ ABSL_GUARDED_BY(mu_);
  bool closing_ ABSL_GUARDED_BY(mu_) = false;
  bool done_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status fatal_ ABSL_GUARDED_BY(mu_);
  int reconnects_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t extra_answers_ ABSL_GUARDED_BY(mu_) = 0;
  std::thread reader_;
};

}  // namespace dynsolid::client
