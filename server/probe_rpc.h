// The Probe RPC (service.proto rpc Probe; docs/haptic.md): the gRPC side of
// a haptic probe stream. The session side, which the simulation thread
// runs, is ProbeHub (probe.h).
#pragma once

#include <grpcpp/grpcpp.h>

#include "dynsolid/service.pb.h"
#include "server/parsed_request.h"

namespace dynsolid::server {

class SessionRegistry;

// A new reactor for one Probe stream (registered by SessionsService).
grpc::ServerBidiReactor<Parsed<ProbeRequest>, ProbeReply>* StartProbe(grpc::CallbackServerContext* context,
                                                              SessionRegistry& registry);

}  // namespace dynsolid::server
