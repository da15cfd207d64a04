// A protobuf message from text format for tests: a parse error fails the
// test (naming the text) instead of crashing it.
#pragma once

#include <string>

#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

namespace dynsolid::testing {

template <typename T>
T Parse(const std::string& text) {
  T msg;
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &msg)) << text;
  return msg;
}

}  // namespace dynsolid::testing
