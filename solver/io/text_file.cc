#include "solver/io/text_file.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <system_error>

namespace dynsolid::io::internal {
namespace {

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

}  // namespace

bool EqualsIgnoreCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    char x = a[i], y = b[i];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

absl::StatusOr<TextFile> TextFile::Read(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) {
    return absl::NotFoundError(Cat(path, ": file not found"));
  }
  if (std::filesystem::is_directory(status)) {
    return absl::InvalidArgumentError(Cat(path, ": is a directory, expected a mesh file"));
  }
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) {
    return absl::InvalidArgumentError(Cat(path, ": cannot open: ", std::strerror(errno)));
  }
  TextFile file;
  file.path_ = path;
  char chunk[1 << 16];
  size_t n;
  while ((n = std::fread(chunk, 1, sizeof(chunk), f)) > 0) file.contents_.append(chunk, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) {
    return absl::InvalidArgumentError(Cat(path, ": read error"));
  }
  return file;
}

bool LineCursor::Next(std::string_view* line) {
  if (rest_.empty()) return false;
  const size_t nl = rest_.find('\n');
  std::string_view l;
  if (nl == std::string_view::npos) {
    l = rest_;
    rest_ = {};
  } else {
    l = rest_.substr(0, nl);
    rest_.remove_prefix(nl + 1);
  }
  if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
  ++line_;
  *line = l;
  return true;
}

bool LineCursor::NextNonBlank(std::string_view* line) {
  std::string_view l;
  while (Next(&l)) {
    if (!Trim(l).empty()) {
      *line = l;
      return true;
    }
  }
  return false;
}

TokenCursor::TokenCursor(const TextFile& file) : file_(&file), rest_(file.contents()) {
  const std::string_view c = file.contents();
  int64_t lines = static_cast<int64_t>(std::count(c.begin(), c.end(), '\n'));
  if (!c.empty() && c.back() != '\n') ++lines;
  last_line_ = lines < 1 ? 1 : lines;
}

bool TokenCursor::Next(std::string_view* token) {
  size_t i = 0;
  const size_t n = rest_.size();
  while (i < n) {
    const char c = rest_[i];
    if (c == '\n') {
      ++current_line_;
    } else if (!IsSpace(c)) {
      break;
    }
    ++i;
  }
  if (i == n) {
    rest_ = {};
    token_line_ = last_line_;  // errors at the end name the file's last line
    return false;
  }
  size_t j = i;
  while (j < n && rest_[j] != '\n' && !IsSpace(rest_[j])) ++j;
  *token = rest_.substr(i, j - i);
  token_line_ = current_line_;
  rest_.remove_prefix(j);
  return true;
}

void TokenCursor::SkipRestOfLine() {
  const size_t nl = rest_.find('\n');
  if (nl == std::string_view::npos) {
    rest_ = {};
  } else {
    rest_.remove_prefix(nl + 1);
    ++current_line_;
  }
}

std::string_view TokenCursor::RestOfLine() {
  const size_t nl = rest_.find('\n');
  std::string_view l = rest_.substr(0, nl);
  SkipRestOfLine();
  return l;
}

void TokenCursor::SkipPastBlankLine() {
  SkipRestOfLine();
  while (!rest_.empty()) {
    const std::string_view l = RestOfLine();
    if (Trim(l).empty()) return;
  }
}

void SplitFields(std::string_view line, std::vector<std::string_view>& fields) {
  fields.clear();
  size_t i = 0;
  const size_t n = line.size();
  while (true) {
    while (i < n && IsSpace(line[i])) ++i;
    if (i == n) return;
    size_t j = i;
    while (j < n && !IsSpace(line[j])) ++j;
    fields.push_back(line.substr(i, j - i));
    i = j;
  }
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && IsSpace(s.front())) s.remove_prefix(1);
  while (!s.empty() && IsSpace(s.back())) s.remove_suffix(1);
  return s;
}

bool ParseInt64(std::string_view token, int64_t* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  return ec == std::errc() && ptr == end;
}

bool ParseDouble(std::string_view token, double* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  // Out of range (1e999) is reported as not a number: it cannot be stored.
  return ec == std::errc() && ptr == end;
}

std::string Quote(std::string_view token) {
  constexpr size_t kMax = 40;
  std::string out = "'";
  for (size_t i = 0; i < token.size() && i < kMax; ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f) {
      out.push_back(static_cast<char>(c));
    } else {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out.push_back(kHex[c >> 4]);
      out.push_back(kHex[c & 15]);
    }
  }
  if (token.size() > kMax) out += "...";
  out += "'";
  return out;
}

OutputFile::OutputFile(std::string path) : path_(std::move(path)) {
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) SetErrno("cannot open for writing", errno);
  buffer_.reserve(kFlushBytes + 4096);
}

OutputFile::OutputFile(std::string* sink) : sink_(sink) { buffer_.reserve(kFlushBytes + 4096); }

OutputFile::~OutputFile() {
  if (file_ != nullptr) std::fclose(file_);
}

void OutputFile::SetErrno(std::string_view what, int error) {
  if (!status_.ok()) return;
  const std::string message = Cat(path_, ": ", what, ": ", std::strerror(error));
  if (error == ENOENT || error == ENOTDIR) {
    status_ = absl::NotFoundError(message);
  } else if (error == EACCES || error == EPERM || error == EROFS) {
    status_ = absl::PermissionDeniedError(message);
  } else {
    status_ = absl::InternalError(message);
  }
}

void OutputFile::Flush() {
  if (sink_ != nullptr) {
    sink_->append(buffer_);
  } else if (file_ != nullptr && !buffer_.empty() && status_.ok()) {
    if (std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size()) {
      SetErrno("write failed", errno);
    }
  }
  buffer_.clear();
}

OutputFile& OutputFile::Put(double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  return Put(std::string_view(tmp, static_cast<size_t>(r.ptr - tmp)));
}

OutputFile& OutputFile::PutFloat(float v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  return Put(std::string_view(tmp, static_cast<size_t>(r.ptr - tmp)));
}

OutputFile& OutputFile::Put(int64_t v) {
  char tmp[24];
  const auto r = std::to_chars(tmp, tmp + sizeof(tmp), v);
  return Put(std::string_view(tmp, static_cast<size_t>(r.ptr - tmp)));
}

absl::Status OutputFile::Close() {
  Flush();
  if (file_ != nullptr) {
    if (std::fclose(file_) != 0) SetErrno("close failed", errno);
    file_ = nullptr;
  }
  return status_;
}

}  // namespace dynsolid::io::internal
