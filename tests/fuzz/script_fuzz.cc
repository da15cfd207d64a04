// Fuzzes the dynsolid-client script parser (clients/lib/script.h
// ParseScript: one command per line, turned into service.proto Commands and
// client-side actions). Scripts come from users and from shared files.
//
// Invariants: no crash or sanitizer report; a refused script has a message;
// an accepted one has lines numbered within the text, in order, each with
// its verb, and every command line carries a command.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>

#include "clients/lib/script.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const absl::string_view text(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<dynsolid::client::Script> script = dynsolid::client::ParseScript(text, "fuzz.txt");
  if (!script.ok()) {
    FUZZ_CHECK(!script.status().message().empty(), "a refused script without a message");
    return 0;
  }
  const int64_t lines = std::count(text.begin(), text.end(), '\n') + 1;
  int previous = 0;
  for (const dynsolid::client::ScriptLine& l : script->lines) {
    FUZZ_CHECK(l.line > previous && l.line <= lines, "line %d after %d, of %lld", l.line,
               previous, static_cast<long long>(lines));
    previous = l.line;
    FUZZ_CHECK(!l.verb.empty(), "line %d without a verb", l.line);
    if (l.kind == dynsolid::client::ScriptLine::Kind::kCommand) {
      FUZZ_CHECK(l.command.kind_case() != dynsolid::Command::KIND_NOT_SET,
                 "command line %d without a command", l.line);
    }
  }
  return 0;
}
