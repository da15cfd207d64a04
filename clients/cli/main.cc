// dynsolid-client: talks to a dynsolid-server from scripts.
//
//   dynsolid-client [--server HOST:PORT] create --scene block3 [--levels L]
//   dynsolid-client [--server HOST:PORT] create --scene_file my.textproto [--levels L]
//   dynsolid-client [--server HOST:PORT] get --id ID --token TOKEN
//   dynsolid-client [--server HOST:PORT] list
//   dynsolid-client [--server HOST:PORT] close --id ID --token TOKEN
//
// Prints the result as JSON on stdout (the proto3 JSON mapping of the reply,
// field names as in service.proto). Exit codes: 0 done; 1 bad command line;
// 2 the call failed (stderr: "dynsolid-client: CODE: message").
//
// --scene_file reads a scene on this machine and sends its text; the
// server rejects scenes that name a mesh file.
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
#include "absl/strings/str_cat.h"
#include "dynsolid/service.grpc.pb.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "dynsolid-server address, HOST:PORT");
ABSL_FLAG(std::string, scene, "", "create: a built-in scene name (block3, chair, ...)");
ABSL_FLAG(std::string, scene_file, "", "create: a local scene file (.textproto) to send");
ABSL_FLAG(int, levels, -1, "create: subdivision levels 0-4; -1 keeps the scene's");
ABSL_FLAG(std::string, id, "", "get, close: the session id");
ABSL_FLAG(std::string, token, "", "get, close: the session token");
ABSL_FLAG(double, timeout_seconds, 120, "Deadline of each call, in seconds");
ABSL_FLAG(int, max_message_bytes, 4 << 20, "Largest message received, in bytes");

namespace {

constexpr int kUsageError = 1;
constexpr int kCallFailed = 2;

const char kUsage[] =
    "dynsolid-client [--server HOST:PORT] COMMAND [flags]\n"
    "  create --scene NAME | --scene_file FILE [--levels L]\n"
    "  get --id ID --token TOKEN\n"
    "  list\n"
    "  close --id ID --token TOKEN";

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

class Client {
 public:
  explicit Client(const std::string& address) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(absl::GetFlag(FLAGS_max_message_bytes));
    stub_ = dynsolid::Sessions::NewStub(
        grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args));
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
      std::ifstream in(file);
      if (!in) return UsageError(absl::StrCat("cannot read --scene_file ", file));
      std::stringstream text;
      text << in.rdbuf();
      request.set_scene_text(text.str());
    }
    if (absl::GetFlag(FLAGS_levels) != -1) {
      request.set_levels_override(absl::GetFlag(FLAGS_levels));
    }
    dynsolid::Session reply;
    auto context = NewContext();
    return Report(stub_->CreateSession(context.get(), request, &reply), reply);
  }

  int Get() {
    dynsolid::SessionRef ref;
    if (int e = ReadRef(ref); e != 0) return e;
    dynsolid::Session reply;
    auto context = NewContext();
    return Report(stub_->GetSession(context.get(), ref, &reply), reply);
  }

  int List() {
    dynsolid::ListSessionsResponse reply;
    auto context = NewContext();
    return Report(stub_->ListSessions(context.get(), dynsolid::ListSessionsRequest(), &reply),
                  reply);
  }

  int Close() {
    dynsolid::SessionRef ref;
    if (int e = ReadRef(ref); e != 0) return e;
    google::protobuf::Empty reply;
    auto context = NewContext();
    return Report(stub_->CloseSession(context.get(), ref, &reply), reply);
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

  std::unique_ptr<dynsolid::Sessions::Stub> stub_;
};

}  // namespace

int main(int argc, char** argv) {
  absl::SetProgramUsageMessage(kUsage);
  const std::vector<char*> args = absl::ParseCommandLine(argc, argv);
  if (args.size() != 2) return UsageError("expected one command: create, get, list or close");
  const std::string command = args[1];
  Client client(absl::GetFlag(FLAGS_server));
  if (command == "create") return client.Create();
  if (command == "get") return client.Get();
  if (command == "list") return client.List();
  if (command == "close") return client.Close();
  return UsageError(absl::StrCat("unknown command \"", command, "\""));
}
