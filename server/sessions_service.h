// The dynsolid.Sessions gRPC service (proto/dynsolid/service.proto) on the
// callback API. Reactors never block on a build: CreateSession hands the
// build to a WorkQueue and Finishes from there; the other calls only look
// up the registry (a short lock) and Finish at once. Every reactor calls
// Finish exactly once, also when the server shuts down. The streaming calls
// live in streams.h.
#pragma once

#include <functional>

#include <grpcpp/grpcpp.h>

#include "dynsolid/service.grpc.pb.h"
#include "server/replicas.h"
#include "server/session_registry.h"
#include "server/streams.h"
#include "server/work_queue.h"

namespace dynsolid::server {

// Watch is a raw method (streams.h); the others take Parsed<Request>
// (parsed_request.h: bytes that are not a request get INVALID_ARGUMENT with
// a message, on unary calls and streams alike) and reply typed messages.
class SessionsService final
    : public Sessions::WithRawCallbackMethod_Watch<Sessions::CallbackService> {
 public:
  // `registry` and `builds` outlive the service and the gRPC server.
  SessionsService(SessionRegistry& registry, Replicas& replicas, int max_sessions,
                  WorkQueue& builds, WorkQueue& encoders, StreamOptions stream_options);
  SessionsService(const SessionsService&) = delete;
  SessionsService& operator=(const SessionsService&) = delete;

  grpc::ServerUnaryReactor* CreateSession(grpc::CallbackServerContext* context,
                                          const CreateSessionRequest* request,
                                          Session* response) override;
  grpc::ServerUnaryReactor* GetSession(grpc::CallbackServerContext* context,
                                       const SessionRef* request, Session* response) override;
  grpc::ServerUnaryReactor* ListSessions(grpc::CallbackServerContext* context,
                                         const ListSessionsRequest* request,
                                         ListSessionsResponse* response) override;
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context,
                                         const SessionRef* request,
                                         google::protobuf::Empty* response) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* Watch(grpc::CallbackServerContext* context,
                                                    const grpc::ByteBuffer* request) override;
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context,
                                     const SessionRef* request, SessionStats* response) override;
  grpc::ServerUnaryReactor* Inspect(grpc::CallbackServerContext* context,
                                    const InspectRequest* request, InspectReply* response) override;
  grpc::ServerUnaryReactor* Pick(grpc::CallbackServerContext* context, const PickRequest* request,
                                 PickReply* response) override;
  // ListScenes: the built-in scenes' names, descriptions and sizes (made
  // once, on the builds queue).
  grpc::ServerUnaryReactor* ListScenes(grpc::CallbackServerContext* context,
                                       const google::protobuf::Empty* request,
                                       SceneList* response) override;
  // Section: the shape taken on the loop, the cut made on the builds queue.
  grpc::ServerUnaryReactor* Section(grpc::CallbackServerContext* context,
                                    const SectionRequest* request,
                                    SectionReply* response) override;

  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context,
                                          const google::protobuf::Empty* request,
                                          ServerInfo* response) override;

  // GetCommandLog: reads the session's journal on the builds queue.
  grpc::ServerUnaryReactor* GetCommandLog(grpc::CallbackServerContext* context,
                                          const CommandLogRequest* request,
                                          CommandLog* response) override;

 private:
  // Registers the unary method `name` so that its request is parsed here:
  // bytes that do not parse are answered INVALID_ARGUMENT, the rest go to
  // `handler`.
  template <class Request, class Reply>
  void ParseFirst(const char* name,
                  grpc::ServerUnaryReactor* (SessionsService::*handler)(
                      grpc::CallbackServerContext*, const Request*, Reply*));
  // Runs `work` on the builds queue; a call whose work never runs (the
  // server shuts down first) is finished with UNAVAILABLE.
  void OnBuilds(grpc::ServerUnaryReactor* reactor, std::function<void()> work);
  // This server's ServerInfo.
  ServerInfo Info() const;
  // The session as the caller sees it: owner replica and address filled.
  Session ToProto(const SolidSession& s) const;
  // Builds the session here (on the builds queue) and finishes the call.
  void CreateHere(grpc::CallbackServerContext* context, const CreateSessionRequest* request,
                  Session* response, grpc::ServerUnaryReactor* reactor);
  // The peer with the least load below this replica's own, or null (this
  // replica). Asks each peer's GetServerInfo (short deadline; a peer that
  // does not answer, drains or is full is passed over). Blocking.
  Replicas::Peer* ChoosePlace();
  // Creates the session on `peer` for the caller (its deadline and
  // cancellation carried over); builds here instead when the peer cannot.
  void CreateOn(Replicas::Peer* peer, grpc::CallbackServerContext* context,
                const CreateSessionRequest* request, Session* response,
                grpc::ServerUnaryReactor* reactor);

  // The session `ref` names, or null after finishing the call with why not.
  std::shared_ptr<const SolidSession> SessionOrFinish(const SessionRef& ref,
                                                      grpc::ServerUnaryReactor* reactor);

  SessionRegistry& registry_;
  Replicas& replicas_;
  const int max_sessions_;
  WorkQueue& builds_;
  WorkQueue& encoders_;
  const StreamOptions stream_options_;
};

}  // namespace dynsolid::server
