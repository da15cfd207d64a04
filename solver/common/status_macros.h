// Small Status helpers: Debian's Abseil (20220623) ships no status macros.
#pragma once

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#define DYNSOLID_CONCAT_INNER_(a, b) a##b
#define DYNSOLID_CONCAT_(a, b) DYNSOLID_CONCAT_INNER_(a, b)

// Returns the status from the enclosing function if `expr` is not OK.
#define RETURN_IF_ERROR(expr)                     \
  do {                                            \
    ::absl::Status dynsolid_status_ = (expr);     \
    if (!dynsolid_status_.ok()) return dynsolid_status_; \
  } while (0)

// `ASSIGN_OR_RETURN(auto x, MakeX());` declares x from a StatusOr or returns its error.
#define ASSIGN_OR_RETURN(lhs, expr) \
  ASSIGN_OR_RETURN_IMPL_(DYNSOLID_CONCAT_(dynsolid_statusor_, __LINE__), lhs, expr)
#define ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                           \
  if (!tmp.ok()) return std::move(tmp).status(); \
  lhs = std::move(tmp).value()
