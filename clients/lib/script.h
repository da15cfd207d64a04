// The dynsolid-client script language (docs/client.md): one command per
// line, parsed into service.proto Commands plus client-side actions (wait,
// sleep, snapshot). Parsing is pure: no network, no files other than the
// text given.
//
// Errors name the file, the line and the bad token:
//   sculpt.txt:7: force: "at=1,2" needs 3 numbers, got 2
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "dynsolid/service.pb.h"

namespace dynsolid::client {

struct ScriptLine {
  enum class Kind {
    kCommand,    // send `command` (a service.proto Command)
    kWaitSteps,  // wait until the steps of every Step command so far are done
    kWait,       // wait until the session reaches base + `steps`, base the
                 // step at which the last command was applied
    kWaitUntil,  // wait until the session reaches step `steps`
    kSleep,      // sleep `seconds` of wall time
    kSnapshot,   // write the watched surface as `name` (frames directory)
  };
  Kind kind = Kind::kCommand;
  // 1-based line number in the script file.
  int line = 0;
  // The verb as written ("force", "wait", ...).
  std::string verb;
  Command command;
  // remove / unfix by name: the name of the load / constraint (then the
  // id in `command` is filled in when the script runs); empty: the id given.
  std::string ref;
  // force / pressure / fix with name=...: the name the reply's id gets.
  std::string name;
  int64_t steps = 0;
  double seconds = 0;
};

struct Script {
  std::string file;  // as given to ParseScript, for messages
  std::vector<ScriptLine> lines;
  // "file:line" of a script line, for messages.
  std::string Where(const ScriptLine& l) const;
};

// Parses a whole script. On error: InvalidArgument whose message lists
// every bad line (at most 20), one per line, "FILE:LINE: VERB: reason".
absl::StatusOr<Script> ParseScript(absl::string_view text, absl::string_view file);

// The service.proto field name of a command's kind ("add_point_force").
std::string CommandKindName(const Command& command);

}  // namespace dynsolid::client
