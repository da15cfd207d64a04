// Command-line helpers shared by every dynsolid binary: --help that lists
// the binary's own flags with their defaults (exit 0), and HOST:PORT checks.
//
// Why here, header-only, in a directory of its own: the five binaries sit on
// both sides of two walls (clients/ never includes solver/ code, solver/
// never knows the network, server/ sees the solver only through its scene
// API). This header depends on Abseil's flags and strings alone -- no gRPC,
// no solver, no server type -- so each side can include it without crossing
// a wall, and being header-only it adds no library to either side's link
// (the INTERFACE target dynsolid_cmdline only carries the include path and
// Abseil's flag libraries).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "absl/flags/commandlineflag.h"
#include "absl/flags/parse.h"
#include "absl/flags/reflection.h"
#include "absl/flags/usage.h"
#include "absl/flags/usage_config.h"
#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/string_view.h"

namespace dynsolid::cmdline {

// Writes `usage` and every flag defined in `main_file` (the __FILE__ of the
// binary's main, where its ABSL_FLAGs live), sorted by name, each with its
// help text and default.
// The file names Abseil reports (CommandLineFlag::Filename, the usage
// config's filters) have their leading '/' and '.' stripped.
inline absl::string_view WithoutLeadingSlashes(absl::string_view file) {
  while (!file.empty() && (file.front() == '/' || file.front() == '.')) file.remove_prefix(1);
  return file;
}

inline void PrintHelp(std::ostream& out, absl::string_view usage, absl::string_view main_file) {
  std::vector<const absl::CommandLineFlag*> own;
  for (const auto& [name, flag] : absl::GetAllFlags()) {
    if (WithoutLeadingSlashes(flag->Filename()) == WithoutLeadingSlashes(main_file)) {
      own.push_back(flag);
    }
  }
  std::sort(own.begin(), own.end(), [](const absl::CommandLineFlag* a,
                                       const absl::CommandLineFlag* b) {
    return a->Name() < b->Name();
  });
  out << usage << "\n\nFlags:\n";
  for (const absl::CommandLineFlag* flag : own) {
    std::string def = flag->DefaultValue();
    if (flag->IsOfType<std::string>()) def = absl::StrCat("\"", def, "\"");
    out << "  --" << flag->Name() << " (default: " << def << ")\n      " << flag->Help() << "\n";
  }
  out << "\nBoolean flags also take --noNAME. Abseil's own flags: --helpfull, --flagfile=FILE.\n";
}

// absl::ParseCommandLine with a working --help. Abseil (Debian's 20220623)
// lists under --help only flags of a file named after the binary
// (dynsolid-server.cc), so every binary here printed "No flags matched", and
// it exits 1 after any help. Here --help, -help, --helpshort and -h print
// PrintHelp to stdout and exit 0; the usage config also points Abseil's own
// --help=SUBSTRING and --helpshort forms at `main_file`. Pass __FILE__ from
// the binary's main file.
inline std::vector<char*> ParseCommandLine(int argc, char** argv, absl::string_view usage,
                                           absl::string_view main_file) {
  absl::SetProgramUsageMessage(usage);
  const std::string own(main_file);
  absl::FlagsUsageConfig config;
  config.contains_help_flags = [own](absl::string_view file) {
    return WithoutLeadingSlashes(file) == WithoutLeadingSlashes(own);
  };
  config.contains_helpshort_flags = config.contains_help_flags;
  absl::SetFlagsUsageConfig(config);
  for (int i = 1; i < argc; ++i) {
    const absl::string_view arg = argv[i];
    if (arg == "--") break;
    if (arg == "--help" || arg == "-help" || arg == "--helpshort" || arg == "-helpshort" ||
        arg == "-h") {
      PrintHelp(std::cout, usage, main_file);
      std::cout.flush();
      std::exit(0);
    }
  }
  return absl::ParseCommandLine(argc, argv);
}

// Checks that `value` of the flag `flag` (named in the message, e.g.
// "--listen") is HOST:PORT with a port in 1-65535, or 0-65535 when
// `allow_port_zero` (a listener's "pick a free port"). The host may be a
// name, an IPv4 address or a bracketed IPv6 address ("[::1]:50051"). gRPC
// target URIs (a scheme such as "dns:///", "ipv4:", "unix:") are left to
// gRPC when `allow_uri`.
inline absl::Status CheckHostPort(absl::string_view flag, absl::string_view value,
                                  bool allow_port_zero, bool allow_uri = false) {
  const auto bad = [&](absl::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat(flag, " \"", value, "\": ", why));
  };
  if (allow_uri && (value.find("://") != absl::string_view::npos ||
                    value.substr(0, 5) == "unix:" || value.substr(0, 5) == "ipv4:" ||
                    value.substr(0, 5) == "ipv6:")) {
    return absl::OkStatus();
  }
  const size_t colon = value.rfind(':');
  if (colon == absl::string_view::npos) return bad("must be HOST:PORT (no ':PORT')");
  const absl::string_view host = value.substr(0, colon), port = value.substr(colon + 1);
  if (host.empty()) return bad("must be HOST:PORT (empty HOST)");
  if (host.front() == '[') {
    if (host.size() < 3 || host.back() != ']') return bad("an IPv6 HOST must be in brackets, [::1]");
  } else if (host.find(':') != absl::string_view::npos) {
    return bad("an IPv6 HOST must be in brackets, e.g. [::1]:50051");
  } else if (std::any_of(host.begin(), host.end(), [](char c) {
               return !(absl::ascii_isalnum(c) || c == '.' || c == '-' || c == '_');
             })) {
    return bad("HOST may hold letters, digits, '.', '-' and '_' only");
  }
  const int min_port = allow_port_zero ? 0 : 1;
  const std::string range = absl::StrCat(min_port, "-65535");
  if (port.empty() || port.size() > 5 ||
      !std::all_of(port.begin(), port.end(), [](char c) { return absl::ascii_isdigit(c); })) {
    return bad(absl::StrCat("PORT must be a number in ", range, ", got \"", port, "\""));
  }
  int number = 0;
  if (!absl::SimpleAtoi(port, &number) || number < min_port || number > 65535) {
    return bad(absl::StrCat("port ", port, " is outside ", range));
  }
  return absl::OkStatus();
}

// CheckHostPort, or exits with the message on stderr (status 2, the
// binaries' "bad flags" code).
inline void CheckHostPortOrExit(absl::string_view program, absl::string_view flag,
                                absl::string_view value, bool allow_port_zero,
                                bool allow_uri = false) {
  const absl::Status s = CheckHostPort(flag, value, allow_port_zero, allow_uri);
  if (!s.ok()) {
    std::cerr << program << ": " << s.message() << "\n";
    std::exit(2);
  }
}

}  // namespace dynsolid::cmdline
