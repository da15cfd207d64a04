// A small strict JSON reader for tests (reading back the glTF JSON chunk):
// objects, arrays, strings (with \uXXXX escapes below 0x80 and the simple
// escapes), numbers, true/false/null. Not for production use.
#pragma once

#include <cctype>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dynsolid::io::testing {

struct Json {
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject };
  Type type = Type::kNull;
  bool boolean = false;
  double number = 0.0;
  std::string text;
  std::vector<Json> items;                            // array
  std::vector<std::pair<std::string, Json>> members;  // object, in file order

  bool is_object() const { return type == Type::kObject; }
  bool is_array() const { return type == Type::kArray; }
  bool is_number() const { return type == Type::kNumber; }
  bool is_string() const { return type == Type::kString; }

  bool Has(std::string_view key) const {
    for (const auto& [k, v] : members)
      if (k == key) return true;
    return false;
  }
  // The member `key` (a null Json when missing).
  const Json& operator[](std::string_view key) const {
    for (const auto& [k, v] : members)
      if (k == key) return v;
    return Null();
  }
  const Json& operator[](size_t i) const { return i < items.size() ? items[i] : Null(); }
  size_t size() const { return is_array() ? items.size() : members.size(); }

  static const Json& Null() {
    static const Json null;
    return null;
  }
};

class JsonParser {
 public:
  // The value, or nullopt with error() saying where parsing stopped.
  std::optional<Json> Parse(std::string_view text) {
    s_ = text;
    at_ = 0;
    error_.clear();
    Json value;
    if (!Value(value, 0)) return std::nullopt;
    SkipSpace();
    if (at_ != s_.size()) return Fail("trailing characters");
    return value;
  }
  const std::string& error() const { return error_; }

 private:
  std::nullopt_t Fail(const std::string& what) {
    if (error_.empty()) error_ = what + " at byte " + std::to_string(at_);
    return std::nullopt;
  }
  void SkipSpace() {
    while (at_ < s_.size() &&
           (s_[at_] == ' ' || s_[at_] == '\n' || s_[at_] == '\r' || s_[at_] == '\t')) {
      ++at_;
    }
  }
  bool Literal(std::string_view word) {
    if (s_.substr(at_, word.size()) != word) return false;
    at_ += word.size();
    return true;
  }
  bool Value(Json& v, int depth) {
    if (depth > 64) return Fail("nesting too deep"), false;
    SkipSpace();
    if (at_ >= s_.size()) return Fail("unexpected end"), false;
    const char c = s_[at_];
    if (c == '{') return Object(v, depth);
    if (c == '[') return Array(v, depth);
    if (c == '"') {
      v.type = Json::Type::kString;
      return String(v.text);
    }
    if (Literal("true")) {
      v.type = Json::Type::kBool;
      v.boolean = true;
      return true;
    }
    if (Literal("false")) {
      v.type = Json::Type::kBool;
      return true;
    }
    if (Literal("null")) return true;
    return Number(v);
  }
  bool Number(Json& v) {
    const size_t start = at_;
    if (at_ < s_.size() && s_[at_] == '-') ++at_;
    auto digits = [&] {
      const size_t from = at_;
      while (at_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[at_]))) ++at_;
      return at_ > from;
    };
    if (!digits()) return Fail("bad value"), false;
    if (s_[start + (s_[start] == '-' ? 1 : 0)] == '0' && at_ - start > 1 + (s_[start] == '-')) {
      return Fail("leading zero"), false;
    }
    if (at_ < s_.size() && s_[at_] == '.') {
      ++at_;
      if (!digits()) return Fail("bad fraction"), false;
    }
    if (at_ < s_.size() && (s_[at_] == 'e' || s_[at_] == 'E')) {
      ++at_;
      if (at_ < s_.size() && (s_[at_] == '+' || s_[at_] == '-')) ++at_;
      if (!digits()) return Fail("bad exponent"), false;
    }
    v.type = Json::Type::kNumber;
    v.number = std::strtod(std::string(s_.substr(start, at_ - start)).c_str(), nullptr);
    return true;
  }
  bool String(std::string& out) {
    ++at_;  // opening quote
    while (at_ < s_.size()) {
      const char c = s_[at_++];
      if (c == '"') return true;
      if (static_cast<unsigned char>(c) < 0x20) return Fail("control byte in string"), false;
      if (c != '\\') {
        out.push_back(c);
        continue;
      }
      if (at_ >= s_.size()) break;
      const char e = s_[at_++];
      // The one-letter escapes and what they stand for, at the same place.
      constexpr std::string_view kEscapes = "\"\\/bfnrt";
      constexpr std::string_view kEscaped = "\"\\/\b\f\n\r\t";
      if (const size_t k = kEscapes.find(e); k != std::string_view::npos) {
        out.push_back(kEscaped[k]);
        continue;
      }
      if (e != 'u') return Fail("bad escape"), false;
      if (at_ + 4 > s_.size()) return Fail("short \\u escape"), false;
      const long code = std::strtol(std::string(s_.substr(at_, 4)).c_str(), nullptr, 16);
      if (code >= 0x80) return Fail("\\u escape beyond ASCII (not supported)"), false;
      out.push_back(static_cast<char>(code));
      at_ += 4;
    }
    return Fail("unterminated string"), false;
  }
  // Past a container's opening byte: whether `close` follows at once (an
  // empty container, then closed).
  bool OpensEmpty(char close) {
    ++at_;
    SkipSpace();
    return at_ < s_.size() && s_[at_] == close ? (++at_, true) : false;
  }
  // After an item of a container closed by `close`: 1 when a comma follows
  // (another item), 0 when `close` does (closed), -1 otherwise (failed).
  int AfterItem(char close) {
    SkipSpace();
    if (at_ < s_.size() && s_[at_] == ',') return ++at_, 1;
    if (at_ < s_.size() && s_[at_] == close) return ++at_, 0;
    return Fail(std::string("expected , or ") + close), -1;
  }
  bool Array(Json& v, int depth) {
    v.type = Json::Type::kArray;
    if (OpensEmpty(']')) return true;
    while (true) {
      v.items.emplace_back();
      if (!Value(v.items.back(), depth + 1)) return false;
      if (const int next = AfterItem(']'); next <= 0) return next == 0;
    }
  }
  bool Object(Json& v, int depth) {
    v.type = Json::Type::kObject;
    if (OpensEmpty('}')) return true;
    while (true) {
      SkipSpace();
      if (at_ >= s_.size() || s_[at_] != '"') return Fail("expected a key"), false;
      std::string key;
      if (!String(key)) return false;
      if (v.Has(key)) return Fail("duplicate key " + key), false;
      SkipSpace();
      if (at_ >= s_.size() || s_[at_] != ':') return Fail("expected :"), false;
      ++at_;
      v.members.emplace_back(std::move(key), Json());
      if (!Value(v.members.back().second, depth + 1)) return false;
      if (const int next = AfterItem('}'); next <= 0) return next == 0;
    }
  }

  std::string_view s_;
  size_t at_ = 0;
  std::string error_;
};

}  // namespace dynsolid::io::testing
