// For targets that parse protobuf messages: libprotobuf logs every string
// field with invalid UTF-8 it parses (to stderr, the slowest part of such a
// run); the parse result is what the code under test sees, so the log is
// dropped. Call from LLVMFuzzerInitialize.
#pragma once

#include <google/protobuf/stubs/logging.h>

namespace dynsolid::fuzz {

inline void QuietProtobuf() { google::protobuf::SetLogHandler(nullptr); }

}  // namespace dynsolid::fuzz
