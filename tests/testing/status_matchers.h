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

// StatusIs(code): the code alone.
MATCHER_P(StatusIs, code, "has code " + std::string(absl::StatusCodeToString(code))) {
  const absl::Status& s = GetStatus(arg);
  *result_listener << "status is " << s.ToString();
  return s.code() == code;
}

}  // namespace dynsolid::testing

#define ASSERT_OK(expr) ASSERT_THAT((expr), ::dynsolid::testing::IsOk())
#define EXPECT_OK(expr) EXPECT_THAT((expr), ::dynsolid::testing::IsOk())

#define DYNSOLID_CONCAT_INNER(a, b) a##b
#define DYNSOLID_CONCAT(a, b) DYNSOLID_CONCAT_INNER(a, b)
// ASSERT_OK_AND_ASSIGN(T x, expr): asserts expr (a StatusOr) is OK and moves
// its value into the declaration.
#define ASSERT_OK_AND_ASSIGN(decl, expr)                                    \
  auto DYNSOLID_CONCAT(statusor_, __LINE__) = (expr);                       \
  ASSERT_OK(DYNSOLID_CONCAT(statusor_, __LINE__));                          \
  decl = *std::move(DYNSOLID_CONCAT(statusor_, __LINE__))
