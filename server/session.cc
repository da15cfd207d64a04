#include "server/session.h"

#include <google/protobuf/timestamp.pb.h>

namespace dynsolid::server {
namespace {

void SetTimestamp(absl::Time t, google::protobuf::Timestamp* out) {
  const absl::Duration since_epoch = t - absl::UnixEpoch();
  const int64_t seconds = absl::ToInt64Seconds(since_epoch);
  out->set_seconds(seconds);
  out->set_nanos(static_cast<int32_t>(
      absl::ToInt64Nanoseconds(since_epoch - absl::Seconds(seconds))));
}

}  // namespace

Session SolidSession::ToProto() const {
  Session s;
  s.set_id(id_);
  s.set_token(token_);
  s.set_scene_name(scene_name_);
  SetTimestamp(created_, s.mutable_created());
  *s.mutable_stats() = stats_;
  s.set_time_step(loop_->time_step());
  return s;
}

ListSessionsResponse::Entry SolidSession::ToListEntry() const {
  ListSessionsResponse::Entry e;
  e.set_id(id_);
  e.set_scene_name(scene_name_);
  SetTimestamp(created_, e.mutable_created());
  return e;
}

}  // namespace dynsolid::server
