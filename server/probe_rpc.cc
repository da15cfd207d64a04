// The Probe RPC's reactor: one per stream, on gRPC's threads. It finds the
// session, attaches a ProbeChannel to its ProbeHub (probe.h), hands each
// pose to the channel and writes the replies the simulation thread offers.
#include "server/probe_rpc.h"

#include <memory>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "server/grpc_status.h"
#include "server/log.h"
#include "server/probe.h"
#include "server/session_loop.h"
#include "server/session_registry.h"

namespace dynsolid::server {

namespace {

class ProbeReactor final : public grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply> {
 public:
  ProbeReactor(grpc::CallbackServerContext* context, SessionRegistry& registry)
      : context_(context), registry_(registry) {
    StartRead(&read_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      if (channel_ != nullptr) {
        channel_->ReadsDone();
      } else {
        Finish(grpc::Status::OK);  // closed before naming a session
      }
      return;
    }
    if (channel_ != nullptr && channel_->ended()) return;
    // Bytes that are not a ProbeRequest end the stream with why.
    if (absl::Status s = read_.parsed ? Handle() : NotAMessage(read_); !s.ok()) {
      if (channel_ != nullptr) {
        channel_->Stop(s);
      } else {
        Finish(ToGrpcStatus(s));
      }
      return;
    }
    StartRead(&read_);
  }
  void OnWriteDone(bool ok) override {
    if (channel_ != nullptr) channel_->OnWriteDone(ok);
  }
  void OnCancel() override {
    if (channel_ != nullptr) channel_->Stop(absl::CancelledError("the client cancelled"));
  }
  void OnDone() override {
    if (channel_ != nullptr) {
      const ProbeStats st = channel_->Stats();
      SessionLog().info("session {}: probe {} left after {} poses ({} refused), {} models",
                        session_->id(), st.probe_id(), st.poses_received(), st.poses_rejected(),
                        st.models_sent());
      session_->loop().probes().Detach(channel_.get());
    }
    delete this;
  }

 private:
  absl::Status Handle() {
    if (channel_ == nullptr) {
      if (!request_.has_session()) {
        return absl::InvalidArgumentError("session: required in the first ProbeRequest");
      }
      absl::StatusOr<std::shared_ptr<const SolidSession>> s =
          registry_.Get(request_.session().id(), request_.session().token());
      if (!s.ok()) return s.status();
      session_ = *std::move(s);
      absl::StatusOr<std::shared_ptr<ProbeChannel>> c =
          session_->loop().probes().Attach(this, request_.options());
      if (!c.ok()) return c.status();
      channel_ = *std::move(c);
      // Visible to the simulation thread (which writes to it) only now that
      // OnWriteDone can reach it.
      session_->loop().probes().Activate(channel_);
      SessionLog().info("session {}: probe {} from {}", session_->id(), channel_->id(),
                        context_->peer());
    } else if (request_.has_session()) {
      if (request_.session().id() != session_->id()) {
        return absl::InvalidArgumentError(absl::StrCat("session.id: this stream is for session ",
                                                       session_->id(), ", got \"",
                                                       request_.session().id(), "\""));
      }
      if (!session_->TokenMatches(request_.session().token())) {
        return absl::PermissionDeniedError(
            absl::StrCat("SessionRef.token does not match session ", session_->id()));
      }
    }
    if (request_.has_pose()) {
      channel_->Receive(request_.pose(), session_->loop().probes().limits());
    }
    return absl::OkStatus();
  }

  grpc::CallbackServerContext* const context_;
  SessionRegistry& registry_;
  std::shared_ptr<const SolidSession> session_;
  std::shared_ptr<ProbeChannel> channel_;
  Parsed<ProbeRequest> read_;
  ProbeRequest& request_ = read_.message;
};

}  // namespace

grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* StartProbe(grpc::CallbackServerContext* context,
                                                              SessionRegistry& registry) {
  return new ProbeReactor(context, registry);
}

}  // namespace dynsolid::server
