// The streaming RPCs' reactors (gRPC callback API): Watch (server
// streaming) and Commands (bidirectional). One write in flight per stream;
// the next starts from OnWriteDone. Reactions never block and never touch
// the solid: Watch takes immutable snapshots the simulation thread
// publishes and encodes them on the encoder pool; Commands enqueues into
// the session loop and writes the replies it releases. gRPC calls
// (StartWrite, StartRead, Finish) are made with no lock held, because a
// reaction may run inline. Every reactor calls Finish exactly once.
#pragma once

#include <memory>

#include <grpcpp/grpcpp.h>

#include "dynsolid/service.pb.h"
#include "server/parsed_request.h"
#include "server/session_registry.h"
#include "server/work_queue.h"

namespace dynsolid::server {

struct StreamOptions {
  double watch_hz = 60;
  double max_watch_hz = 240;
};

// Watch is registered as a raw method: `request` is a serialized
// WatchRequest, and frames are written as bytes (one serialized body shared
// by the watchers in the same state, then each watcher's own fields). On
// the wire it is the typed method of service.proto.
grpc::ServerWriteReactor<grpc::ByteBuffer>* StartWatch(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request,
                                                       SessionRegistry& registry,
                                                       WorkQueue& encoders,
                                                       const StreamOptions& options);

grpc::ServerBidiReactor<Parsed<CommandRequest>, CommandReply>* StartCommands(
    grpc::CallbackServerContext* context, SessionRegistry& registry);

}  // namespace dynsolid::server
