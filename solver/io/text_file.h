// Internal helpers of the io module: whole-file reading, line and token
// cursors that track line numbers, strict number parsing, and a buffered
// output file. Not part of the public API (include the format headers).
//
// Every parse error is absl::InvalidArgumentError("path:line: message"), so
// a user can jump to the offending line.
#pragma once

#include <charconv>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace dynsolid::io::internal {

// String concatenation for messages. (Debian's Abseil has its own
// absl::string_view, which absl::StrCat requires; this takes std types.)
namespace cat_internal {
inline void Append(std::string& s, std::string_view v) { s.append(v); }
inline void Append(std::string& s, const char* v) { s.append(v); }
inline void Append(std::string& s, const std::string& v) { s.append(v); }
inline void Append(std::string& s, char c) { s.push_back(c); }
template <typename T>
requires(std::is_integral_v<T> && !std::is_same_v<T, char> &&
         !std::is_same_v<T, bool>) void Append(std::string& s, T v) {
  char tmp[24];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  s.append(tmp, r.ptr);
}
inline void Append(std::string& s, double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  s.append(tmp, r.ptr);
}
}  // namespace cat_internal

template <typename... Args>
std::string Cat(const Args&... args) {
  std::string s;
  (cat_internal::Append(s, args), ...);
  return s;
}

// ASCII case-insensitive equality.
bool EqualsIgnoreCase(std::string_view a, std::string_view b);

// The bytes of one file, read at once (files of a million nodes are tens of
// megabytes; one read is the fastest way in).
class TextFile {
 public:
  // NotFound when the file does not exist, InvalidArgument when it cannot
  // be read (a directory, no permission).
  static absl::StatusOr<TextFile> Read(const std::string& path);

  const std::string& path() const { return path_; }
  std::string_view contents() const { return contents_; }

  // InvalidArgument "path:line: message".
  absl::Status Error(int64_t line, std::string_view message) const {
    return absl::InvalidArgumentError(Cat(path_, ":", line, ": ", message));
  }

 private:
  std::string path_;
  std::string contents_;
};

// Walks the lines of a file. A line excludes its "\n" and a trailing "\r".
class LineCursor {
 public:
  explicit LineCursor(const TextFile& file) : file_(&file), rest_(file.contents()) {}

  // The next line, or false at the end of the file.
  bool Next(std::string_view* line);
  // The next line that is not blank (only spaces, tabs), or false at the end.
  bool NextNonBlank(std::string_view* line);

  // 1-based number of the line last returned (at the end: the last line).
  int64_t line() const { return line_ == 0 ? 1 : line_; }
  bool at_end() const { return rest_.empty(); }
  size_t remaining_bytes() const { return rest_.size(); }

  absl::Status Error(std::string_view message) const { return file_->Error(line(), message); }
  absl::Status ErrorAt(int64_t line, std::string_view message) const {
    return file_->Error(line, message);
  }

 private:
  const TextFile* file_;
  std::string_view rest_;
  int64_t line_ = 0;
};

// Walks whitespace-separated tokens (free-format files such as VTK legacy),
// remembering the line of each token.
class TokenCursor {
 public:
  explicit TokenCursor(const TextFile& file);

  // The next token, or false at the end of the file.
  bool Next(std::string_view* token);
  // Skips the rest of the current line and whole lines up to and including
  // the next blank line (used for VTK METADATA blocks).
  void SkipPastBlankLine();
  // Moves to the start of the next line (drops the rest of the current one).
  void SkipRestOfLine();
  // The rest of the current line (without the newline), consuming it.
  std::string_view RestOfLine();

  // Line of the last token returned (or of the current position at the end).
  int64_t line() const { return token_line_; }
  size_t remaining_bytes() const { return rest_.size(); }

  absl::Status Error(std::string_view message) const { return file_->Error(line(), message); }
  absl::Status ErrorAt(int64_t line, std::string_view message) const {
    return file_->Error(line, message);
  }

 private:
  const TextFile* file_;
  std::string_view rest_;
  int64_t current_line_ = 1;  // line of rest_.front()
  int64_t token_line_ = 1;
  int64_t last_line_ = 1;  // number of the file's last line
};

// Splits `line` at spaces and tabs into `fields` (cleared first).
void SplitFields(std::string_view line, std::vector<std::string_view>& fields);

// Trims spaces, tabs and a trailing '\r'.
std::string_view Trim(std::string_view s);

// Strict parsers: the whole token must be the number. A leading '+' is
// allowed. ParseDouble accepts "nan" and "inf" (callers check finiteness to
// report them precisely).
bool ParseInt64(std::string_view token, int64_t* value);
bool ParseDouble(std::string_view token, double* value);

// A token for messages: quoted, shortened when long, control bytes escaped.
std::string Quote(std::string_view token);

// How many items to reserve for a declared count, so that an absurd count
// in a small (or hostile) file cannot exhaust memory before parsing fails:
// at most one item per `min_bytes_per_item` bytes left in the file.
inline size_t SafeReserve(int64_t declared, size_t remaining_bytes, size_t min_bytes_per_item) {
  if (declared <= 0) return 0;
  const size_t cap = remaining_bytes / (min_bytes_per_item == 0 ? 1 : min_bytes_per_item) + 1;
  return static_cast<size_t>(declared) < cap ? static_cast<size_t>(declared) : cap;
}

// Buffered text output. Errors (cannot open, disk full) are kept and
// returned by Close(): NotFound for a missing directory, PermissionDenied,
// else Internal; the message names the path and the system error.
class OutputFile {
 public:
  explicit OutputFile(std::string path);
  // In memory: what is put is appended to *sink (nothing fails).
  explicit OutputFile(std::string* sink);
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;
  ~OutputFile();

  bool ok() const { return status_.ok(); }
  const absl::Status& status() const { return status_; }

  OutputFile& Put(std::string_view s) {
    buffer_.append(s);
    if (buffer_.size() >= kFlushBytes) Flush();
    return *this;
  }
  OutputFile& Put(char c) {
    buffer_.push_back(c);
    return *this;
  }
  // Shortest text that reads back to the same value.
  OutputFile& Put(double v);
  OutputFile& PutFloat(float v);
  OutputFile& Put(int64_t v);
  OutputFile& Put(int32_t v) { return Put(static_cast<int64_t>(v)); }

  // Flushes and closes; returns the first error met.
  absl::Status Close();

 private:
  static constexpr size_t kFlushBytes = 1 << 20;
  void Flush();
  void SetErrno(std::string_view what, int error);

  std::string path_;
  std::FILE* file_ = nullptr;
  std::string* sink_ = nullptr;
  std::string buffer_;
  absl::Status status_;
};

}  // namespace dynsolid::io::internal
