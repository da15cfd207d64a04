// A minimal streaming JSON writer for reports (stats.json, bench output).
// Keys keep insertion order; numbers are written with full precision.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace dynsolid {

class JsonWriter {
 public:
  JsonWriter() { out_ = "{"; first_.push_back(true); }

  JsonWriter& Begin(std::string_view key) {
    KeyPrefix(key);
    out_ += "{";
    first_.push_back(true);
    return *this;
  }
  JsonWriter& End() {
    first_.pop_back();
    out_ += '\n';
    out_.append(2 * first_.size(), ' ');
    out_ += '}';
    return *this;
  }
  JsonWriter& Add(std::string_view key, double v) {
    KeyPrefix(key);
    out_ += std::isfinite(v) ? absl::StrFormat("%.17g", v) : std::string("null");
    return *this;
  }
  JsonWriter& Add(std::string_view key, int64_t v) {
    KeyPrefix(key);
    absl::StrAppend(&out_, v);
    return *this;
  }
  JsonWriter& Add(std::string_view key, int v) { return Add(key, static_cast<int64_t>(v)); }
  JsonWriter& Add(std::string_view key, bool v) {
    KeyPrefix(key);
    out_ += v ? "true" : "false";
    return *this;
  }
  JsonWriter& Add(std::string_view key, std::string_view v) {
    KeyPrefix(key);
    out_ += Quote(v);
    return *this;
  }
  JsonWriter& Add(std::string_view key, const char* v) { return Add(key, std::string_view(v)); }

  // The finished document (closes the top-level object).
  std::string Finish() {
    while (!first_.empty()) End();
    out_ += "\n";
    return out_;
  }

  static std::string Quote(std::string_view s) {
    std::string q = "\"";
    for (char c : s) {
      switch (c) {
        case '"': q += "\\\""; break;
        case '\\': q += "\\\\"; break;
        case '\n': q += "\\n"; break;
        case '\t': q += "\\t"; break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            q += absl::StrFormat("\\u%04x", static_cast<int>(c));
          } else {
            q += c;
          }
      }
    }
    return q + "\"";
  }

 private:
  void KeyPrefix(std::string_view key) {
    if (!first_.back()) out_ += ",";
    first_.back() = false;
    out_ += '\n';
    out_.append(2 * first_.size(), ' ');
    out_ += Quote(key);
    out_ += ": ";
  }

  std::string out_;
  std::vector<bool> first_;
};

}  // namespace dynsolid
