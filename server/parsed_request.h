// Requests that do not parse are the handler's to answer.
//
// gRPC's generated callback handlers deserialize a request before the
// service sees it, and when the bytes are not a message they answer a unary
// call with UNIMPLEMENTED and an empty message, and end a stream's read as
// if the client had half-closed (the stream then finishes OK). Here the
// Sessions methods are registered with Parsed<Request> as their request
// type: its SerializationTraits always succeed and record whether the bytes
// parsed, so the service refuses them with INVALID_ARGUMENT and a message
// that says what was sent (SessionsService's constructor, streams.cc,
// probe.cc).
#pragma once

#include <string>

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace dynsolid::server {

template <class Message>
struct Parsed {
  Message message;
  bool parsed = true;     // false: the bytes were not a Message
  size_t bytes = 0;       // their length
};

// INVALID_ARGUMENT for a request that did not parse.
template <class Message>
absl::Status NotAMessage(const Parsed<Message>& p) {
  return absl::InvalidArgumentError(absl::StrCat(
      Message::descriptor()->name(), ": not a valid message (", p.bytes,
      " bytes that do not parse as ", Message::descriptor()->full_name(), ")"));
}

}  // namespace dynsolid::server

namespace grpc {

template <class Message>
class SerializationTraits<dynsolid::server::Parsed<Message>, void> {
 public:
  static Status Serialize(const dynsolid::server::Parsed<Message>& p, ByteBuffer* buffer,
                          bool* own_buffer) {
    return SerializationTraits<Message>::Serialize(p.message, buffer, own_buffer);
  }
  // Always OK: a failure is recorded in `parsed` for the handler.
  static Status Deserialize(ByteBuffer* buffer, dynsolid::server::Parsed<Message>* p) {
    p->bytes = buffer != nullptr ? buffer->Length() : 0;
    p->parsed = SerializationTraits<Message>::Deserialize(buffer, &p->message).ok();
    if (!p->parsed) p->message.Clear();
    return Status::OK;
  }
};

}  // namespace grpc
