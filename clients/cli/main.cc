// dynsolid-client: talks to a dynsolid-server from scripts.
//
//   dynsolid-client [--server HOST:PORT] create --scene block3 [--levels L]
//   dynsolid-client [--server HOST:PORT] create --scene_file my.textproto [--levels L]
//   dynsolid-client [--server HOST:PORT] get --id ID --token TOKEN
//   dynsolid-client [--server HOST:PORT] list
//   dynsolid-client [--server HOST:PORT] close --id ID --token TOKEN
//   dynsolid-client [--server HOST:PORT] stats --id ID --token TOKEN
//   dynsolid-client [--server HOST:PORT] run --script FILE
//       (--scene NAME | --scene_file FILE | --id ID --token TOKEN)
//       [--frames_dir DIR] [--format obj,vtu] [--record_every N]
//       [--fields displacement,strain,stiffness,mass] [--json FILE] ...
//   dynsolid-client [--server HOST:PORT] export --id ID --token TOKEN --format glb
//       [--level L] [--out FILE] [--color_field displacement]
//   dynsolid-client check --script FILE
//
// create/get/list/close/stats print the result as JSON on stdout (the proto3 JSON
// mapping of the reply, field names as in service.proto). `run` runs a
// script of commands against a new or joined session while watching it
// (docs/client.md), prints latency and frame rate, and with --json writes
// the full report. `check` only parses a script. Exit codes: 0 done; 1 bad
// command line or script (stderr: "FILE:LINE: ..."); 2 a call failed
// (stderr: "dynsolid-client: CODE: message"); 3 the script ran but
// stopped early (a rejected command, a wait that timed out).
//
// --scene_file reads a scene on this machine and sends its text; the
// server rejects scenes that name a mesh file.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "clients/lib/script.h"
#include "clients/lib/session_runner.h"
#include "cmdline/cmdline.h"
#include "dynsolid/service.grpc.pb.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "dynsolid-server address, HOST:PORT");
ABSL_FLAG(std::string, tls_ca, "",
          "PEM file of the root certificates to trust: connect with TLS (empty: plaintext)");
ABSL_FLAG(std::string, scene, "", "create, run: a built-in scene name (block3, chair, ...)");
ABSL_FLAG(std::string, scene_file, "", "create, run: a local scene file (.textproto) to send");
ABSL_FLAG(int, levels, -1, "create, run: subdivision levels 0-4; -1 keeps the scene's");
ABSL_FLAG(bool, start_paused, false,
          "create, run: open the session paused at step 0 (it moves on step/resume)");
ABSL_FLAG(std::string, id, "", "get, close, run: the session id (run: join it)");
ABSL_FLAG(std::string, token, "", "get, close, run: the session token");
ABSL_FLAG(double, timeout_seconds, 120, "Deadline of each call and of each wait line, seconds");
ABSL_FLAG(int, max_message_bytes, 4 << 20, "Largest message received, in bytes");
ABSL_FLAG(std::string, script, "", "run, check: the script file (docs/client.md)");
ABSL_FLAG(std::string, client_id, "",
          "run: the client id of the commands (empty: a random one); keep it to resend");
ABSL_FLAG(bool, watch, true, "run: watch the surface (--nowatch: commands only)");
ABSL_FLAG(double, watch_hz, 0, "run: frames per second asked for (0: the server's default)");
ABSL_FLAG(std::string, fields, "",
          "run: per-vertex fields to watch and record, comma separated: displacement, strain, "
          "stiffness, mass");
ABSL_FLAG(std::string, frames_dir, "",
          "run: directory for recorded frames and snapshots (created if missing)");
ABSL_FLAG(std::string, format, "obj",
          "run: frame file formats, comma separated: obj, vtu; export: one of obj, stl, ply, glb, "
          "vtu, scene (the design as a scene file that create --scene_file takes back)");
ABSL_FLAG(int, record_every, 0,
          "run: record every N-th frame received as frame_<step>.<format> (0: only snapshots)");
ABSL_FLAG(std::string, json, "", "run: write the report as JSON to this file");
ABSL_FLAG(bool, close, true,
          "run: close the session at the end (a joined session: only with --close given)");
ABSL_FLAG(bool, keep_going, false, "run: continue after a rejected command");
ABSL_FLAG(int, break_every, 0,
          "run, testing: drop the command stream after every N-th command (0: never) to "
          "exercise reconnect and resend");
ABSL_FLAG(bool, verbose, false, "run: print each script line and every reconnect on stderr");
ABSL_FLAG(std::string, origin, "", "pick: the ray's origin X,Y,Z (metres)");
ABSL_FLAG(std::string, direction, "", "pick: the ray's direction X,Y,Z");
ABSL_FLAG(int, level, -1, "export: subdivision level 0-6 (-1: the session's own)");
ABSL_FLAG(std::string, out, "",
          "export: the file to write (empty: the name the server gives, in this directory)");
ABSL_FLAG(std::string, color_field, "",
          "export: glb vertex colours from a field (displacement, displacement_magnitude)");
ABSL_FLAG(double, reconnect_seconds, 30,
          "run: give up when no stream has worked for this long");

namespace {

constexpr int kUsageError = 1;
constexpr int kCallFailed = 2;
constexpr int kScriptStopped = 3;

const char kUsage[] =
    "dynsolid-client [--server HOST:PORT] COMMAND [flags]\n"
    "  create --scene NAME | --scene_file FILE [--levels L] [--start_paused]\n"
    "  get --id ID --token TOKEN\n"
    "  list                          (this replica's sessions)\n"
    "  info                          (the server's replica name, address, load and peers)\n"
    "  close --id ID --token TOKEN\n"
    "  stats --id ID --token TOKEN\n"
    "  mesh --id ID --token TOKEN     (the control mesh: ids for topology edits)\n"
    "  loads --id ID --token TOKEN    (the active loads and constraints, every client's)\n"
    "  history --id ID --token TOKEN  (everyone's undo entries: who did what, undone or not)\n"
    "  pick --id ID --token TOKEN --origin X,Y,Z --direction X,Y,Z\n"
    "  export --id ID --token TOKEN --format obj|stl|ply|glb|vtu|scene [--level L] [--out FILE]\n"
    "      [--color_field displacement] [--verbose]   (the current design, any level)\n"
    "  run --script FILE (--scene NAME | --scene_file FILE | --id ID --token TOKEN)\n"
    "      [--frames_dir DIR] [--format obj,vtu] [--record_every N] [--fields LIST]\n"
    "      [--json FILE] [--start_paused] [--levels L] [--noclose] [--keep_going]\n"
    "  check --script FILE";

int UsageError(const std::string& message) {
  std::cerr << "dynsolid-client: " << message << "\nusage: " << kUsage << "\n";
  return kUsageError;
}

// The gRPC code's name, as in the gRPC documentation.
const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::UNKNOWN: return "UNKNOWN";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED: return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE: return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS: return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}

// Prints the reply as JSON (0) or the failed call's status (2).
int Report(const grpc::Status& status, const google::protobuf::Message& reply) {
  if (!status.ok()) {
    std::cerr << "dynsolid-client: " << CodeName(status.error_code()) << ": "
              << status.error_message() << "\n";
    return kCallFailed;
  }
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = true;
  std::string json;
  if (!google::protobuf::util::MessageToJsonString(reply, &json, options).ok()) {
    std::cerr << "dynsolid-client: cannot print the reply as JSON\n";
    return kCallFailed;
  }
  std::cout << json;
  if (json.empty() || json.back() != '\n') std::cout << "\n";
  return 0;
}

bool ReadFile(const std::string& path, std::string* text) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::stringstream s;
  s << in.rdbuf();
  *text = s.str();
  return true;
}

class Client {
 public:
  explicit Client(bool close_given) : close_given_(close_given) {
    dynsolid::client::ChannelOptions options;
    options.address = absl::GetFlag(FLAGS_server);
    options.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
    const std::string ca = absl::GetFlag(FLAGS_tls_ca);
    if (!ca.empty() && !ReadFile(ca, &options.tls_root_certs)) {
      ca_error_ = absl::StrCat("cannot read --tls_ca ", ca);
    }
    channels_ = dynsolid::client::ChannelFactoryFor(options);
    stub_ = dynsolid::Sessions::NewStub(channels_());
  }

  const std::string& ca_error() const { return ca_error_; }

  // One unary call (fn makes it with the context given), following a
  // redirect to the replica that owns the session.
  template <typename Fn>
  grpc::Status Call(Fn fn) {
    for (int redirects = 0;; ++redirects) {
      auto context = NewContext();
      const grpc::Status s = fn(context.get());
      if (redirects == dynsolid::client::kMaxRedirects || !channels_.Follow(s)) return s;
      stub_ = dynsolid::Sessions::NewStub(channels_());
    }
  }

  int Create() {
    const std::string name = absl::GetFlag(FLAGS_scene);
    const std::string file = absl::GetFlag(FLAGS_scene_file);
    if (name.empty() == file.empty()) {
      return UsageError("create needs exactly one of --scene NAME and --scene_file FILE");
    }
    dynsolid::CreateSessionRequest request;
    if (!name.empty()) {
      request.set_builtin_scene(name);
    } else {
      std::string text;
      if (!ReadFile(file, &text)) return UsageError(absl::StrCat("cannot read --scene_file ", file));
      request.set_scene_text(text);
    }
    if (absl::GetFlag(FLAGS_levels) != -1) {
      request.set_levels_override(absl::GetFlag(FLAGS_levels));
    }
    request.set_start_paused(absl::GetFlag(FLAGS_start_paused));
    dynsolid::Session reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->CreateSession(c, request, &reply); }), reply);
  }

  int Get() {
    dynsolid::SessionRef ref;
    if (int e = ReadRef(ref); e != 0) return e;
    dynsolid::Session reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->GetSession(c, ref, &reply); }), reply);
  }

  int Info() {
    dynsolid::ServerInfo reply;
    return Report(Call([&](grpc::ClientContext* c) {
                    return stub_->GetServerInfo(c, google::protobuf::Empty(), &reply);
                  }),
                  reply);
  }

  int List() {
    dynsolid::ListSessionsResponse reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->ListSessions(c, dynsolid::ListSessionsRequest(), &reply); }),
                  reply);
  }

  int Close() {
    dynsolid::SessionRef ref;
    if (int e = ReadRef(ref); e != 0) return e;
    google::protobuf::Empty reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->CloseSession(c, ref, &reply); }), reply);
  }

  int Stats() {
    dynsolid::SessionRef ref;
    if (int e = ReadRef(ref); e != 0) return e;
    dynsolid::SessionStats reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->GetStats(c, ref, &reply); }), reply);
  }

  int Mesh() {
    dynsolid::InspectRequest request;
    if (int e = ReadRef(*request.mutable_session()); e != 0) return e;
    request.set_control_mesh(true);
    dynsolid::InspectReply reply;
    const grpc::Status status = Call([&](grpc::ClientContext* c) { return stub_->Inspect(c, request, &reply); });
    return Report(status, reply.control_mesh());
  }

  int Loads() {
    dynsolid::InspectRequest request;
    if (int e = ReadRef(*request.mutable_session()); e != 0) return e;
    request.set_loads(true);
    dynsolid::InspectReply reply;
    const grpc::Status status = Call([&](grpc::ClientContext* c) { return stub_->Inspect(c, request, &reply); });
    dynsolid::InspectReply out;
    out.set_step(reply.step());
    out.set_time(reply.time());
    *out.mutable_loads() = reply.loads();
    *out.mutable_constraints() = reply.constraints();
    *out.mutable_gravity() = reply.gravity();
    return Report(status, out);
  }

  int History() {
    dynsolid::InspectRequest request;
    if (int e = ReadRef(*request.mutable_session()); e != 0) return e;
    request.set_history(true);
    dynsolid::InspectReply reply;
    const grpc::Status status = Call([&](grpc::ClientContext* c) { return stub_->Inspect(c, request, &reply); });
    return Report(status, reply.history());
  }

  int Pick() {
    dynsolid::PickRequest request;
    if (int e = ReadRef(*request.mutable_session()); e != 0) return e;
    for (const auto& [flag, out] :
         {std::pair{"--origin", request.mutable_origin()},
          std::pair{"--direction", request.mutable_direction()}}) {
      const std::string text =
          absl::GetFlag(std::string(flag) == "--origin" ? FLAGS_origin : FLAGS_direction);
      std::vector<std::string> parts = absl::StrSplit(text, ',');
      double v[3];
      if (parts.size() != 3 || !absl::SimpleAtod(parts[0], &v[0]) ||
          !absl::SimpleAtod(parts[1], &v[1]) || !absl::SimpleAtod(parts[2], &v[2])) {
        return UsageError(absl::StrCat(flag, " needs X,Y,Z, got \"", text, "\""));
      }
      out->set_x(v[0]);
      out->set_y(v[1]);
      out->set_z(v[2]);
    }
    dynsolid::PickReply reply;
    return Report(Call([&](grpc::ClientContext* c) { return stub_->Pick(c, request, &reply); }), reply);
  }

  // The current design as a file: streamed in chunks (progress on stderr
  // with --verbose), checked for gaps and size, then written.
  int Export() {
    dynsolid::ExportRequest request;
    if (int e = ReadRef(*request.mutable_session()); e != 0) return e;
    const std::string format = absl::GetFlag(FLAGS_format);
    dynsolid::ExportRequest::Format f;
    if (!dynsolid::ExportRequest::Format_Parse(absl::AsciiStrToUpper(format), &f) ||
        f == dynsolid::ExportRequest::FORMAT_UNSPECIFIED) {
      return UsageError(absl::StrCat("--format ", format, ": export takes obj, stl, ply, glb, vtu or scene"));
    }
    request.set_format(f);
    if (absl::GetFlag(FLAGS_level) >= 0) request.set_level(absl::GetFlag(FLAGS_level));
    request.set_color_field(absl::GetFlag(FLAGS_color_field));
    auto context = NewContext();
    std::unique_ptr<grpc::ClientReader<dynsolid::ExportChunk>> reader =
        stub_->Export(context.get(), request);
    dynsolid::ExportChunk chunk, first;
    std::string bytes;
    bool have_first = false;
    while (reader->Read(&chunk)) {
      if (!have_first) {
        first = chunk;
        first.clear_data();
        have_first = true;
        bytes.reserve(static_cast<size_t>(std::max<int64_t>(0, chunk.total_bytes())));
      }
      if (chunk.offset() != static_cast<int64_t>(bytes.size()) ||
          chunk.total_bytes() != first.total_bytes()) {
        std::cerr << "dynsolid-client: export: a chunk at offset " << chunk.offset() << " of "
                  << chunk.total_bytes() << " bytes after " << bytes.size() << " received\n";
        context->TryCancel();
        reader->Finish();
        return kCallFailed;
      }
      bytes.append(chunk.data());
      if (absl::GetFlag(FLAGS_verbose)) {
        std::cerr << absl::StrFormat("export: %lld of %lld bytes (%.0f %%)\n",
                                     static_cast<long long>(bytes.size()),
                                     static_cast<long long>(first.total_bytes()),
                                     first.total_bytes() > 0
                                         ? 100.0 * bytes.size() / first.total_bytes()
                                         : 100.0);
      }
    }
    const grpc::Status status = reader->Finish();
    if (!status.ok()) return Report(status, first);
    if (!have_first || static_cast<int64_t>(bytes.size()) != first.total_bytes()) {
      std::cerr << "dynsolid-client: export: " << bytes.size() << " bytes received of "
                << first.total_bytes() << "\n";
      return kCallFailed;
    }
    const std::string path =
        absl::GetFlag(FLAGS_out).empty() ? first.file_name() : absl::GetFlag(FLAGS_out);
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      std::cerr << "dynsolid-client: export: cannot write " << path << "\n";
      return kCallFailed;
    }
    first.set_file_name(path);
    return Report(status, first);
  }

  int Run(const dynsolid::client::Script& script) {
    namespace dc = dynsolid::client;
    dc::RunOptions o;
    const std::string name = absl::GetFlag(FLAGS_scene);
    const std::string file = absl::GetFlag(FLAGS_scene_file);
    const std::string id = absl::GetFlag(FLAGS_id);
    if (int(!name.empty()) + int(!file.empty()) + int(!id.empty()) != 1) {
      return UsageError("run needs exactly one of --scene NAME, --scene_file FILE, --id ID");
    }
    o.builtin_scene = name;
    if (!file.empty() && !ReadFile(file, &o.scene_text)) {
      return UsageError(absl::StrCat("cannot read --scene_file ", file));
    }
    if (!id.empty()) {
      o.join.set_id(id);
      o.join.set_token(absl::GetFlag(FLAGS_token));
    }
    o.levels = absl::GetFlag(FLAGS_levels);
    o.start_paused = absl::GetFlag(FLAGS_start_paused);
    o.client_id = absl::GetFlag(FLAGS_client_id);
    o.watch = absl::GetFlag(FLAGS_watch);
    o.watcher.rate_hz = absl::GetFlag(FLAGS_watch_hz);
    for (absl::string_view f : absl::StrSplit(absl::GetFlag(FLAGS_fields), ',', absl::SkipEmpty())) {
      if (f == "displacement") {
        o.watcher.displacement = true;
      } else if (f == "strain") {
        o.watcher.strain = true;
      } else if (f == "stiffness") {
        o.watcher.stiffness = true;
      } else if (f == "mass") {
        o.watcher.mass = true;
      } else {
        return UsageError(absl::StrCat("--fields: unknown field \"", f,
                                       "\" (displacement, strain, stiffness, mass)"));
      }
    }
    o.write_obj = o.write_vtu = false;
    for (absl::string_view f : absl::StrSplit(absl::GetFlag(FLAGS_format), ',', absl::SkipEmpty())) {
      if (f == "obj") {
        o.write_obj = true;
      } else if (f == "vtu") {
        o.write_vtu = true;
      } else {
        return UsageError(absl::StrCat("--format: unknown format \"", f, "\" (obj, vtu)"));
      }
    }
    o.watcher.record_every = absl::GetFlag(FLAGS_record_every);
    if (o.watcher.record_every < 0) return UsageError("--record_every must be >= 0");
    o.frames_dir = absl::GetFlag(FLAGS_frames_dir);
    if (o.watcher.record_every > 0 && o.frames_dir.empty()) {
      return UsageError("--record_every needs --frames_dir");
    }
    if (!o.frames_dir.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(o.frames_dir, ec);
      if (ec) return UsageError(absl::StrCat("cannot create --frames_dir ", o.frames_dir, ": ",
                                             ec.message()));
    }
    // A joined session stays open unless --close is given explicitly.
    o.close_at_end = absl::GetFlag(FLAGS_close);
    if (!id.empty() && !close_given_) o.close_at_end = false;
    o.keep_going = absl::GetFlag(FLAGS_keep_going);
    const absl::Duration timeout = absl::Seconds(absl::GetFlag(FLAGS_timeout_seconds));
    o.wait_timeout = o.call_timeout = timeout;
    o.commands.break_every = absl::GetFlag(FLAGS_break_every);
    o.commands.reconnect_timeout = absl::Seconds(absl::GetFlag(FLAGS_reconnect_seconds));
    o.watcher.reconnect_timeout = o.commands.reconnect_timeout;

    if (absl::GetFlag(FLAGS_verbose)) {
      const auto start = std::chrono::steady_clock::now();
      o.log = [start](const std::string& message) {
        const double t =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::cerr << absl::StrFormat("[%8.3f s] %s\n", t, message);
      };
    }
    absl::StatusOr<dc::RunReport> report = dc::RunScript(channels_, script, o);
    if (!report.ok()) {
      std::cerr << "dynsolid-client: "
                << CodeName(static_cast<grpc::StatusCode>(report.status().code())) << ": "
                << report.status().message() << "\n";
      return kCallFailed;
    }
    std::cout << dc::ReportText(*report);
    if (report->created && !report->closed) {
      // Whoever created it may join it again (run --id ID --token TOKEN).
      std::cout << "session " << report->session.id() << " left open, token " << report->token
                << "\n";
    }
    const std::string json = absl::GetFlag(FLAGS_json);
    if (!json.empty()) {
      std::ofstream out(json, std::ios::trunc);
      out << dc::ReportJson(*report);
      if (!out) {
        std::cerr << "dynsolid-client: cannot write --json " << json << "\n";
        return kCallFailed;
      }
    }
    if (!report->status.ok()) {
      std::cerr << "dynsolid-client: " << report->status.message() << "\n";
      return kScriptStopped;
    }
    return 0;
  }

 private:
  static std::unique_ptr<grpc::ClientContext> NewContext() {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int64_t>(
                              1000 * absl::GetFlag(FLAGS_timeout_seconds))));
    return context;
  }

  static int ReadRef(dynsolid::SessionRef& ref) {
    ref.set_id(absl::GetFlag(FLAGS_id));
    ref.set_token(absl::GetFlag(FLAGS_token));
    if (ref.id().empty()) return UsageError("--id is required");
    // An empty --token is sent as is: the server answers PERMISSION_DENIED.
    return 0;
  }

  dynsolid::client::ChannelFactory channels_;
  std::unique_ptr<dynsolid::Sessions::Stub> stub_;
  std::string ca_error_;
  const bool close_given_;
};

// Reads and parses --script; prints the errors (exit code 1) or returns 0.
int LoadScript(dynsolid::client::Script* script) {
  const std::string path = absl::GetFlag(FLAGS_script);
  if (path.empty()) return UsageError("--script FILE is required");
  std::string text;
  if (!ReadFile(path, &text)) return UsageError(absl::StrCat("cannot read --script ", path));
  absl::StatusOr<dynsolid::client::Script> parsed = dynsolid::client::ParseScript(text, path);
  if (!parsed.ok()) {
    std::cerr << parsed.status().message() << "\n";
    return kUsageError;
  }
  *script = std::move(*parsed);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  bool close_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--close", 0) == 0 || a.rfind("--noclose", 0) == 0) close_given = true;
  }
  const std::vector<char*> args = dynsolid::cmdline::ParseCommandLine(argc, argv, kUsage, __FILE__);
  if (absl::Status s = dynsolid::cmdline::CheckHostPort("--server", absl::GetFlag(FLAGS_server),
                                                        /*allow_port_zero=*/false,
                                                        /*allow_uri=*/true);
      !s.ok()) {
    return UsageError(std::string(s.message()));
  }
  if (args.size() != 2) {
    return UsageError(
        "expected one command: create, get, list, close, stats, mesh, pick, export, run or check");
  }
  const std::string command = args[1];
  if (command == "check") {
    dynsolid::client::Script script;
    if (int e = LoadScript(&script); e != 0) return e;
    std::cout << script.file << ": " << script.lines.size() << " lines OK\n";
    return 0;
  }
  Client client(close_given);
  if (!client.ca_error().empty()) return UsageError(client.ca_error());
  if (command == "create") return client.Create();
  if (command == "get") return client.Get();
  if (command == "list") return client.List();
  if (command == "info") return client.Info();
  if (command == "close") return client.Close();
  if (command == "stats") return client.Stats();
  if (command == "mesh") return client.Mesh();
  if (command == "loads") return client.Loads();
  if (command == "history") return client.History();
  if (command == "pick") return client.Pick();
  if (command == "export") return client.Export();
  if (command == "run") {
    dynsolid::client::Script script;
    if (int e = LoadScript(&script); e != 0) return e;
    return client.Run(script);
  }
  return UsageError(absl::StrCat("unknown command \"", command, "\""));
}
