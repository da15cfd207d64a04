// One place that rejects non-finite numbers anywhere in a request: a
// reflection walk over every double and float field (singular, repeated,
// nested messages, map values), so a new message or field is covered
// without new code.
#pragma once

#include <google/protobuf/message.h>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace dynsolid::server {

// OK when every double/float in `message` is finite; otherwise
// InvalidArgument naming the first offending field by its path from
// `prefix` ("command.add_point_force.force.x: must be finite, got nan";
// repeated fields as "name[i]").
absl::Status CheckFinite(const google::protobuf::Message& message, absl::string_view prefix);

}  // namespace dynsolid::server
