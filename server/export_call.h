// Export (service.proto): the current design, taken at a step boundary by
// the simulation thread, made on the builds queue (solver/export), and
// streamed to the caller in chunks; the first chunk names the file and its
// size, every chunk carries its offset, so a client shows progress.
#pragma once

#include <grpcpp/grpcpp.h>

#include "dynsolid/service.grpc.pb.h"
#include "server/session_registry.h"
#include "server/work_queue.h"

namespace dynsolid::server {

// The reactor of one Export call (it deletes itself when done). `registry`
// and `builds` outlive the server.
grpc::ServerWriteReactor<ExportChunk>* StartExport(grpc::CallbackServerContext* context,
                                                   const ExportRequest* request,
                                                   SessionRegistry& registry, WorkQueue& builds);

// A reactor that only finishes with `status` (a request that did not parse).
grpc::ServerWriteReactor<ExportChunk>* RefuseExport(const absl::Status& status);

}  // namespace dynsolid::server
