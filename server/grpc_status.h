// The one place an absl::Status becomes a grpc::Status: the server edge.
// Everything below server/ (the solver, the session registry) reports
// absl::Status; reactors convert with ToGrpcStatus just before Finish.
#pragma once

#include <grpcpp/support/status.h>

#include "absl/status/status.h"

namespace dynsolid::server {

// Same canonical code (absl and gRPC share the numbering), same message.
// Payloads (e.g. a SessionRedirect) travel as the details of an RpcStatus
// (google.rpc.Status on the wire) in grpc-status-details-bin, each as an Any
// with the payload's type URL. An unknown code becomes UNKNOWN.
grpc::Status ToGrpcStatus(const absl::Status& status);

}  // namespace dynsolid::server
