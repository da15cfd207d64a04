// GoogleTest matchers for absl::Status / StatusOr (Debian's Abseil has none).
#pragma once

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace dynsolid::testing {

inline const absl::Status& GetStatus(const absl::Status& s) { return s; }
template <typename T>
const absl::Status& GetStatus(const absl::StatusOr<T>& s) { return s.status(); }

MATCHER(IsOk, "is OK") {
  const absl::Status& s = GetStatus(arg);
  if (!s.ok()) *result_listener << "status is " << s.ToString();
  return s.ok();
}

// StatusIs(code, message_matcher): code equal and message matching.
MATCHER_P2(StatusIs, code, message_matcher,
           "has code " + std::string(absl::StatusCodeToString(code))) {
  const absl::Status& s = GetStatus(arg);
  *result_listener << "status is " << s.ToString();
  return s.code() == code &&
         ::testing::Value(std::string(s.message()), message_matcher);
}

}  // namespace dynsolid::testing

#define ASSERT_OK(expr) ASSERT_THAT((expr), ::dynsolid::testing::IsOk())
#define EXPECT_OK(expr) EXPECT_THAT((expr), ::dynsolid::testing::IsOk())
