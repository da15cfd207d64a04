#include "clients/lib/session_runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <random>
#include <thread>

#include <google/protobuf/util/json_util.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace dynsolid::client {
namespace {

using Clock = std::chrono::steady_clock;

std::chrono::system_clock::time_point DeadlineIn(absl::Duration d) {
  return std::chrono::system_clock::now() + absl::ToChronoNanoseconds(d);
}


std::string RandomClientId() {
  std::random_device rd;
  std::mt19937_64 rng((static_cast<uint64_t>(rd()) << 32) ^ rd());
  return absl::StrFormat("client-%016x", rng());
}

const char* CodeName(int code) {
  static const char* kNames[] = {"OK",
                                 "CANCELLED",
                                 "UNKNOWN",
                                 "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED",
                                 "NOT_FOUND",
                                 "ALREADY_EXISTS",
                                 "PERMISSION_DENIED",
                                 "RESOURCE_EXHAUSTED",
                                 "FAILED_PRECONDITION",
                                 "ABORTED",
                                 "OUT_OF_RANGE",
                                 "UNIMPLEMENTED",
                                 "INTERNAL",
                                 "UNAVAILABLE",
                                 "DATA_LOSS",
                                 "UNAUTHENTICATED"};
  return code >= 0 && code <= 16 ? kNames[code] : "UNKNOWN";
}

// Unary calls that ride out a server restart: a call goes on a fresh
// channel when the current one is not READY (a channel whose server went
// away may stay stuck; see channel.h), and UNAVAILABLE is retried on a
// fresh channel (backoff 50 ms doubling to 1 s) until `patience` has
// passed. Only for idempotent calls (not CreateSession).
class Caller {
 public:
  Caller(ChannelFactory channels, absl::Duration patience, LogFn log)
      : channels_(std::move(channels)), patience_(patience), log_(std::move(log)) {
    Renew();
  }

  // fn(Sessions::Stub&) makes one attempt (with its own ClientContext).
  template <typename Fn>
  grpc::Status Call(Fn fn) {
    const Clock::time_point give_up = Clock::now() + absl::ToChronoNanoseconds(patience_);
    int backoff_ms = 50;
    int redirects = 0;
    for (;;) {
      if (used_) {
        const grpc_connectivity_state state = channel_->GetState(false);
        if (state != GRPC_CHANNEL_READY) {
          if (log_) log_(absl::StrCat("calls: channel state ", state, ", using a new channel"));
          Renew();
        }
      }
      used_ = true;
      const grpc::Status s = fn(*stub_);
      if (redirects < kMaxRedirects && channels_.Follow(s)) {
        // The session lives on another replica: ask it there.
        if (log_) log_(absl::StrCat("calls: ", s.error_message()));
        ++redirects;
        Renew();
        continue;
      }
      if (s.error_code() != grpc::StatusCode::UNAVAILABLE || Clock::now() > give_up) return s;
      if (log_) log_(absl::StrCat("calls: ", s.error_message(), "; retrying on a new channel"));
      std::this_thread::sleep_for(std::chrono::milliseconds(backoff_ms));
      backoff_ms = std::min(2 * backoff_ms, 1000);
      Renew();
    }
  }
  Sessions::Stub& stub() {
    used_ = true;
    return *stub_;
  }

  // A new channel (to where the factory points now).
  void Renew() {
    channel_ = channels_();
    stub_ = Sessions::NewStub(channel_);
    used_ = false;
  }

 private:
  const ChannelFactory channels_;
  const absl::Duration patience_;
  const LogFn log_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<Sessions::Stub> stub_;
  bool used_ = false;  // a call was made on channel_ (a new one is IDLE, not READY)
};

// Runs the lines of one script; keeps the state the lines share.
class Run {
 public:
  Run(Caller& stub, const Script& script, const RunOptions& options, RunReport& report,
      CommandChannel& commands, Watcher* watcher, std::string token)
      : token_(std::move(token)),
        stub_(stub),
        script_(script),
        options_(options),
        report_(report),
        commands_(commands),
        watcher_(watcher) {}

  absl::Status Execute() {
    for (const ScriptLine& line : script_.lines) {
      absl::Status s = Line(line);
      if (!s.ok()) return s;
    }
    return Barrier();
  }

  int64_t known_step() const { return known_step_; }

 private:
  absl::Status Line(const ScriptLine& line) {
    const std::string where = absl::StrCat(script_.Where(line), ": ", line.verb);
    if (options_.log) options_.log(where);
    switch (line.kind) {
      case ScriptLine::Kind::kCommand: {
        Command command = line.command;
        if (!line.ref.empty()) {
          // remove / unfix by name: the id from the naming line's reply.
          auto it = named_.find(line.ref);
          if (it == named_.end()) {
            return absl::InternalError(absl::StrCat(where, ": \"", line.ref, "\" is not bound"));
          }
          absl::StatusOr<CommandReply> reply =
              commands_.Wait(it->second.seq, options_.wait_timeout);
          if (!reply.ok()) return Annotate(where, reply.status());
          if (reply->code() != 0) {
            return absl::FailedPreconditionError(
                absl::StrCat(where, ": \"", line.ref, "\" (line ", it->second.line,
                             ") was rejected, so there is nothing to ",
                             line.verb));
          }
          if (command.has_remove_load()) {
            command.mutable_remove_load()->set_load_id(reply->load_id());
          } else if (command.has_move_drag()) {
            command.mutable_move_drag()->set_load_id(reply->load_id());
          } else {
            command.mutable_unfix()->set_constraint_id(reply->constraint_id());
          }
        }
        absl::StatusOr<uint64_t> seq = commands_.Send(command, where);
        if (!seq.ok()) return Annotate(where, seq.status());
        if (!line.name.empty()) named_[line.name] = Named{*seq, line.line};
        return absl::OkStatus();
      }
      case ScriptLine::Kind::kWaitSteps: {
        if (absl::Status s = Barrier(); !s.ok()) return s;
        absl::StatusOr<int64_t> at = WaitForStepsDone(where);
        if (!at.ok()) return at.status();
        known_step_ = std::max(known_step_, *at);
        return absl::OkStatus();
      }
      case ScriptLine::Kind::kWait:
      case ScriptLine::Kind::kWaitUntil: {
        if (absl::Status s = Barrier(); !s.ok()) return s;
        const int64_t target =
            line.kind == ScriptLine::Kind::kWait ? last_applied_ + line.steps : line.steps;
        absl::StatusOr<InspectReply> at = WaitForStep(target, where);
        if (!at.ok()) return at.status();
        known_step_ = std::max(known_step_, at->step());
        return absl::OkStatus();
      }
      case ScriptLine::Kind::kSleep:
        std::this_thread::sleep_for(
            std::chrono::duration<double>(line.seconds));
        return absl::OkStatus();
      case ScriptLine::Kind::kSnapshot: {
        if (absl::Status s = Barrier(); !s.ok()) return s;
        if (watcher_ == nullptr) {
          return absl::FailedPreconditionError(
              absl::StrCat(where, ": needs the watcher (run without --nowatch)"));
        }
        if (options_.frames_dir.empty()) {
          return absl::FailedPreconditionError(
              absl::StrCat(where, ": needs a frames directory (--frames_dir)"));
        }
        absl::StatusOr<Surface> s = watcher_->WaitForStep(known_step_, options_.wait_timeout);
        if (!s.ok()) return Annotate(where, s.status());
        SnapshotFile snap{line.name, s->step, line.line, {}};
        const std::string stem = absl::StrCat(options_.frames_dir, "/", line.name);
        if (options_.write_obj) {
          if (absl::Status w = WriteObj(*s, stem + ".obj"); !w.ok()) return Annotate(where, w);
          snap.files.push_back(stem + ".obj");
        }
        if (options_.write_vtu) {
          if (absl::Status w = WriteVtu(*s, stem + ".vtu"); !w.ok()) return Annotate(where, w);
          snap.files.push_back(stem + ".vtu");
        }
        report_.snapshots.push_back(std::move(snap));
        return absl::OkStatus();
      }
    }
    return absl::OkStatus();
  }

  static absl::Status Annotate(const std::string& where, const absl::Status& s) {
    return absl::Status(s.code(), absl::StrCat(where, ": ", s.message()));
  }

  // Every command sent so far is answered; stops at the first rejection
  // (unless keep_going).
  absl::Status Barrier() {
    if (absl::Status s = commands_.WaitAll(options_.wait_timeout); !s.ok()) return s;
    for (const CommandRecord& r : commands_.Records()) {
      if (!r.answered || r.seq <= checked_seq_) continue;
      checked_seq_ = r.seq;
      last_applied_ = std::max(last_applied_, r.reply.applied_step());
      known_step_ = std::max(known_step_, r.reply.applied_step());
      if (r.reply.code() != 0 && !options_.keep_going) {
        return absl::Status(static_cast<absl::StatusCode>(r.reply.code()),
                            absl::StrCat(r.label, ": rejected: ", CodeName(r.reply.code()), ": ",
                                         r.reply.message()));
      }
    }
    return absl::OkStatus();
  }

  absl::StatusOr<InspectReply> WaitForStep(int64_t step, const std::string& where) {
    InspectRequest request;
    *request.mutable_session() = Ref();
    request.set_wait_for_step(step);
    InspectReply reply;
    const grpc::Status s = stub_.Call([&](Sessions::Stub& stub) {
      grpc::ClientContext context;
      context.set_deadline(DeadlineIn(options_.wait_timeout));
      return stub.Inspect(&context, request, &reply);
    });
    if (s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
      return absl::DeadlineExceededError(absl::StrCat(
          where, ": the session did not reach step ", step, " within ",
          absl::FormatDuration(options_.wait_timeout),
          " (is it paused? \"step N\" or \"resume\" make it move)"));
    }
    if (!s.ok()) return Annotate(where, ToAbslStatus(s, "Inspect"));
    return reply;
  }

  // Polls GetStats until no steps of Step commands are left; returns the
  // step the session is at then.
  absl::StatusOr<int64_t> WaitForStepsDone(const std::string& where) {
    const Clock::time_point give_up =
        Clock::now() + absl::ToChronoNanoseconds(options_.wait_timeout);
    int poll_us = 500;
    for (;;) {
      SessionStats stats;
      const grpc::Status s = stub_.Call([&](Sessions::Stub& stub) {
        grpc::ClientContext context;
        context.set_deadline(DeadlineIn(options_.call_timeout));
        return stub.GetStats(&context, Ref(), &stats);
      });
      if (!s.ok()) return Annotate(where, ToAbslStatus(s, "GetStats"));
      if (!stats.last_error().empty()) {
        return absl::AbortedError(absl::StrCat(where, ": the session stopped at step ",
                                               stats.step(), ": ", stats.last_error()));
      }
      if (stats.steps_remaining() == 0) return stats.step();
      if (Clock::now() > give_up) {
        return absl::DeadlineExceededError(absl::StrCat(
            where, ": ", stats.steps_remaining(), " steps still to take after ",
            absl::FormatDuration(options_.wait_timeout), " (at step ", stats.step(), ")"));
      }
      std::this_thread::sleep_for(std::chrono::microseconds(poll_us));
      poll_us = std::min(2 * poll_us, 20000);
    }
  }

  SessionRef Ref() const {
    SessionRef r;
    r.set_id(report_.session.id());
    r.set_token(token_);
    return r;
  }

  struct Named {
    uint64_t seq;
    int line;
  };
  const std::string token_;
  Caller& stub_;
  const Script& script_;
  const RunOptions& options_;
  RunReport& report_;
  CommandChannel& commands_;
  Watcher* watcher_;
  std::map<std::string, Named> named_;
  uint64_t checked_seq_ = 0;
  int64_t last_applied_ = 0;
  int64_t known_step_ = 0;
};

// Appends a JSON string literal.
void JsonString(std::string& out, absl::string_view s) {
  out += '"';
  for (char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          absl::StrAppendFormat(&out, "\\u%04x", static_cast<unsigned char>(c));
        } else {
          out += c;
        }
    }
  }
  out += '"';
}

// A finite number as JSON (non-finite: null).
std::string JsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  return absl::StrFormat("%.17g", v);
}

std::string JsonArray3(const std::array<double, 3>& v) {
  return absl::StrCat("[", JsonNumber(v[0]), ", ", JsonNumber(v[1]), ", ", JsonNumber(v[2]), "]");
}

std::string MessageJson(const google::protobuf::Message& m) {
  google::protobuf::util::JsonPrintOptions options;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = true;
  std::string json;
  if (!google::protobuf::util::MessageToJsonString(m, &json, options).ok()) return "null";
  return json;
}

}  // namespace

absl::StatusOr<RunReport> RunScript(const ChannelFactory& channels, const Script& script,
                                    const RunOptions& options) {
  const Clock::time_point start = Clock::now();
  Caller caller(channels, options.commands.reconnect_timeout, options.log);
  RunReport report;
  report.script_file = script.file;
  report.script_lines = static_cast<int>(script.lines.size());
  report.client_id = options.client_id.empty() ? RandomClientId() : options.client_id;

  // The session.
  std::string token;
  if (!options.join.id().empty()) {
    const grpc::Status s = caller.Call([&](Sessions::Stub& stub) {
      grpc::ClientContext context;
      context.set_deadline(DeadlineIn(options.call_timeout));
      return stub.GetSession(&context, options.join, &report.session);
    });
    if (!s.ok()) return ToAbslStatus(s, absl::StrCat("GetSession ", options.join.id()));
    token = options.join.token();
  } else {
    CreateSessionRequest request;
    if (!options.builtin_scene.empty()) {
      request.set_builtin_scene(options.builtin_scene);
    } else {
      request.set_scene_text(options.scene_text);
    }
    if (options.levels != -1) request.set_levels_override(options.levels);
    request.set_start_paused(options.start_paused);
    grpc::ClientContext context;
    context.set_deadline(DeadlineIn(options.call_timeout));
    // Not retried: a lost answer would leave a second session behind.
    const grpc::Status s = caller.stub().CreateSession(&context, request, &report.session);
    if (!s.ok()) return ToAbslStatus(s, "CreateSession");
    token = report.session.token();
    report.created = true;
  }
  // The session may live on another replica: every later call goes there.
  if (channels.Follow(report.session)) {
    if (options.log) options.log(absl::StrCat("session ", report.session.id(), " lives at ",
                                              report.session.address()));
    caller.Renew();
  }
  report.session.clear_token();
  report.token = token;
  SessionRef ref;
  ref.set_id(report.session.id());
  ref.set_token(token);

  std::unique_ptr<Watcher> watcher;
  if (options.watch) {
    WatcherOptions w = options.watcher;
    w.log = options.log;
    w.frames_dir = options.frames_dir;
    w.write_obj = options.write_obj;
    w.write_vtu = options.write_vtu;
    w.client_id = report.client_id;  // a frame right after each of its own commands
    watcher = std::make_unique<Watcher>(channels, ref, w);
  }
  CommandChannelOptions command_options = options.commands;
  command_options.log = options.log;
  auto commands = std::make_unique<CommandChannel>(channels, ref, report.client_id,
                                                   command_options);
  if (watcher != nullptr) {
    // The first frame (a keyframe) before any command: displacements in
    // the report are measured from where the session was when the run began.
    absl::StatusOr<Surface> first = watcher->WaitForStep(0, options.wait_timeout);
    if (!first.ok()) {
      report.status = first.status();
      if (options.log) options.log(absl::StrCat("no first frame: ", first.status().ToString()));
    }
  }
  Run run(caller, script, options, report, *commands, watcher.get(), token);
  if (report.status.ok()) report.status = run.Execute();

  if (options.log) options.log(absl::StrCat("script done: ", report.status.ToString()));
  // The end: where the session is, what the watcher holds.
  InspectReply at_end;
  {
    InspectRequest request;
    *request.mutable_session() = ref;
    const grpc::Status s = caller.Call([&](Sessions::Stub& stub) {
      grpc::ClientContext context;
      context.set_deadline(DeadlineIn(options.call_timeout));
      return stub.Inspect(&context, request, &at_end);
    });
    if (!s.ok() && report.status.ok()) report.status = ToAbslStatus(s, "Inspect");
  }
  if (watcher != nullptr) {
    absl::StatusOr<Surface> last =
        watcher->WaitForStep(std::max(at_end.step(), run.known_step()), absl::Seconds(10));
    report.final_surface = last.ok() ? *last : watcher->Current();
    report.first_surface = watcher->First();
    // Same step on both sides only when the session stands still.
    if (at_end.paused() && report.final_surface.step == at_end.step() &&
        at_end.steps_remaining() == 0) {
      InspectRequest request;
      *request.mutable_session() = ref;
      request.set_surface_positions(true);
      InspectReply exact;
      const grpc::Status s = caller.Call([&](Sessions::Stub& stub) {
        grpc::ClientContext context;
        context.set_deadline(DeadlineIn(options.call_timeout));
        return stub.Inspect(&context, request, &exact);
      });
      const Surface& got = report.final_surface;
      if (s.ok() && exact.step() == got.step &&
          exact.surface_positions_size() == static_cast<int>(got.positions.size())) {
        report.checked = true;
        report.check_step = exact.step();
        report.check_within_bound = true;
        for (int i = 0; i < exact.surface_positions_size(); ++i) {
          const int a = i % 3;
          const double e = std::abs(got.positions[i] - exact.surface_positions(i));
          report.check_max_error[a] = std::max(report.check_max_error[a], e);
          // The bound is half a grid step; allow rounding of the decode.
          if (e > got.error_bound[a] * (1 + 1e-9)) report.check_within_bound = false;
        }
      }
    }
  }
  {
    const grpc::Status s = caller.Call([&](Sessions::Stub& stub) {
      grpc::ClientContext context;
      context.set_deadline(DeadlineIn(options.call_timeout));
      return stub.GetStats(&context, ref, &report.stats);
    });
    if (!s.ok() && report.status.ok()) report.status = ToAbslStatus(s, "GetStats");
  }
  const absl::Status closed = commands->Close(absl::Seconds(30));
  if (!closed.ok() && report.status.ok()) report.status = closed;
  report.commands = commands->Records();
  report.reconnects = commands->reconnects();
  report.extra_answers = commands->extra_answers();
  if (watcher != nullptr) {
    const absl::Status w = watcher->Stop();
    report.watch = watcher->Counts();
    if (!w.ok() && report.status.ok()) report.status = w;
  }
  if (options.close_at_end) {
    google::protobuf::Empty empty;
    const grpc::Status s = caller.Call([&](Sessions::Stub& stub) {
      grpc::ClientContext context;
      context.set_deadline(DeadlineIn(options.call_timeout));
      return stub.CloseSession(&context, ref, &empty);
    });
    if (!s.ok() && report.status.ok()) report.status = ToAbslStatus(s, "CloseSession");
    report.closed = s.ok();
  }
  report.wall_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return report;
}

std::string ReportJson(const RunReport& r) {
  std::vector<double> latencies;
  int ok = 0, rejected = 0, duplicates = 0, resends = 0, answered = 0, rate_limited = 0;
  for (const CommandRecord& c : r.commands) {
    if (!c.answered) continue;
    ++answered;
    latencies.push_back(c.latency_ms);
    if (c.reply.code() == 0) {
      ++ok;
    } else {
      ++rejected;
    }
    if (c.reply.duplicate()) ++duplicates;
    resends += std::max(0, c.writes - 1);
    rate_limited += c.rate_limited;
  }
  std::string j = "{\n";
  absl::StrAppend(&j, "  \"status\": ");
  JsonString(j, r.status.ok() ? "OK" : r.status.ToString());
  absl::StrAppend(&j, ",\n  \"wall_seconds\": ", JsonNumber(r.wall_seconds));
  absl::StrAppend(&j, ",\n  \"session\": {\"id\": ");
  JsonString(j, r.session.id());
  absl::StrAppend(&j, ", \"scene_name\": ");
  JsonString(j, r.session.scene_name());
  absl::StrAppend(&j, ", \"time_step\": ", JsonNumber(r.session.time_step()),
                  ", \"created\": ", r.created ? "true" : "false",
                  ", \"closed\": ", r.closed ? "true" : "false",
                  ", \"solid\": ", MessageJson(r.session.stats()), "}");
  absl::StrAppend(&j, ",\n  \"client_id\": ");
  JsonString(j, r.client_id);
  absl::StrAppend(&j, ",\n  \"script\": {\"file\": ");
  JsonString(j, r.script_file);
  absl::StrAppend(&j, ", \"lines\": ", r.script_lines, "}");
  absl::StrAppend(&j, ",\n  \"commands\": {\"sent\": ", r.commands.size(),
                  ", \"answered\": ", answered, ", \"ok\": ", ok, ", \"rejected\": ", rejected,
                  ", \"duplicate_answers\": ", duplicates, ", \"resends\": ", resends,
                  ", \"rate_limited\": ", rate_limited, ", \"reconnects\": ", r.reconnects,
                  ", \"extra_answers\": ", r.extra_answers,
                  ",\n    \"latency_ms\": {\"median\": ", JsonNumber(Percentile(latencies, 0.5)),
                  ", \"p99\": ", JsonNumber(Percentile(latencies, 0.99)),
                  ", \"max\": ", JsonNumber(Percentile(latencies, 1.0)), "},\n    \"log\": [");
  for (size_t i = 0; i < r.commands.size(); ++i) {
    const CommandRecord& c = r.commands[i];
    absl::StrAppend(&j, i == 0 ? "\n" : ",\n", "      {\"seq\": ", c.seq, ", \"where\": ");
    JsonString(j, c.label);
    absl::StrAppend(&j, ", \"kind\": ");
    JsonString(j, CommandKindName(c.command));
    absl::StrAppend(&j, ", \"answered\": ", c.answered ? "true" : "false",
                    ", \"answers\": ", c.answers, ", \"code\": ", c.reply.code(),
                    ", \"message\": ");
    JsonString(j, c.reply.message());
    absl::StrAppend(&j, ", \"applied_step\": ", c.reply.applied_step(),
                    ", \"duplicate\": ", c.reply.duplicate() ? "true" : "false",
                    ", \"writes\": ", c.writes, ", \"latency_ms\": ", JsonNumber(c.latency_ms));
    if (c.reply.has_load_id()) absl::StrAppend(&j, ", \"load_id\": ", c.reply.load_id());
    if (c.reply.has_constraint_id()) {
      absl::StrAppend(&j, ", \"constraint_id\": ", c.reply.constraint_id());
    }
    absl::StrAppend(&j, ", \"hold_ms\": ", JsonNumber(c.reply.hold_ms()));
    if (c.reply.has_edit()) {
      const EditReport& e = c.reply.edit();
      absl::StrAppend(&j, ", \"edit\": {\"cells_before\": ", e.control_cells_before(),
                      ", \"cells_after\": ", e.control_cells_after(),
                      ", \"elements_after\": ", e.elements_after(),
                      ", \"build_ms\": ", JsonNumber(e.build_ms()), ", \"summary\": ");
      JsonString(j, e.summary());
      absl::StrAppend(&j, "}");
    }
    if (c.reply.has_history()) {
      absl::StrAppend(&j, ", \"history\": {\"undo_depth\": ", c.reply.history().undo_depth(),
                      ", \"redo_depth\": ", c.reply.history().redo_depth(), ", \"what\": ");
      JsonString(j, c.reply.history().what());
      absl::StrAppend(&j, "}");
    }
    if (c.reply.has_saved()) {
      absl::StrAppend(&j, ", \"saved_step\": ", c.reply.saved().step(),
                      ", \"saved_bytes\": ", c.reply.saved().bytes());
    }
    j += "}";
  }
  j += "\n    ]}";
  const WatcherCounts& w = r.watch;
  const double fps = w.seconds > 0 ? (w.frames - 1) / w.seconds : 0;
  absl::StrAppend(&j, ",\n  \"watch\": {\"frames\": ", w.frames, ", \"keyframes\": ", w.keyframes,
                  ", \"deltas\": ", w.deltas, ", \"skipped\": ", w.skipped,
                  ", \"bytes\": ", w.bytes, ", \"field_bytes\": ", w.field_bytes,
                  ", \"raw_float32_bytes\": ", w.raw_float32_bytes,
                  ", \"reconnects\": ", w.reconnects, ", \"first_step\": ", w.first_step,
                  ", \"last_step\": ", w.last_step, ", \"seconds\": ", JsonNumber(w.seconds),
                  ", \"frames_per_second\": ", JsonNumber(fps),
                  ", \"frames_written\": ", w.frames_written, ", \"files\": ", w.files.size(), "}");
  absl::StrAppend(&j, ",\n  \"snapshots\": [");
  for (size_t i = 0; i < r.snapshots.size(); ++i) {
    const SnapshotFile& s = r.snapshots[i];
    absl::StrAppend(&j, i == 0 ? "" : ", ", "{\"name\": ");
    JsonString(j, s.name);
    absl::StrAppend(&j, ", \"step\": ", s.step, ", \"line\": ", s.line, ", \"files\": [");
    for (size_t k = 0; k < s.files.size(); ++k) {
      if (k > 0) j += ", ";
      JsonString(j, s.files[k]);
    }
    j += "]}";
  }
  j += "]";
  const Surface& f = r.final_surface;
  absl::StrAppend(&j, ",\n  \"surface\": {\"step\": ", f.step, ", \"time\": ", JsonNumber(f.time),
                  ", \"vertices\": ", f.vertex_count(), ", \"quads\": ", f.quads.size() / 4);
  if (f.vertex_count() > 0) {
    absl::StrAppend(&j, ", \"bbox_min\": ", JsonArray3(f.BoundsMin()),
                    ", \"bbox_max\": ", JsonArray3(f.BoundsMax()),
                    ", \"error_bound\": ", JsonArray3(f.error_bound));
    const Surface& first = r.first_surface;
    if (first.vertex_count() == f.vertex_count() && first.topology_version == f.topology_version) {
      double max_move = 0;
      for (int i = 0; i < f.vertex_count(); ++i) {
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
          const double d = f.positions[3 * i + a] - first.positions[3 * i + a];
          d2 += d * d;
        }
        max_move = std::max(max_move, std::sqrt(d2));
      }
      absl::StrAppend(&j, ", \"first_step\": ", first.step,
                      ", \"max_moved_since_first\": ", JsonNumber(max_move));
    }
    if (!f.displacement.empty()) {
      absl::StrAppend(&j, ", \"max_displacement\": ",
                      JsonNumber(*std::max_element(f.displacement.begin(), f.displacement.end())));
    }
    if (!f.stiffness.empty()) {
      const auto [lo, hi] = std::minmax_element(f.stiffness.begin(), f.stiffness.end());
      absl::StrAppend(&j, ", \"stiffness_min\": ", JsonNumber(*lo),
                      ", \"stiffness_max\": ", JsonNumber(*hi));
    }
    if (!f.mass.empty()) {
      const auto [lo, hi] = std::minmax_element(f.mass.begin(), f.mass.end());
      absl::StrAppend(&j, ", \"mass_min\": ", JsonNumber(*lo), ", \"mass_max\": ", JsonNumber(*hi));
    }
  }
  j += "}";
  absl::StrAppend(&j, ",\n  \"check\": {\"done\": ", r.checked ? "true" : "false",
                  ", \"step\": ", r.check_step, ", \"max_error\": ",
                  JsonArray3(r.check_max_error), ", \"within_bound\": ",
                  r.check_within_bound ? "true" : "false", "}");
  absl::StrAppend(&j, ",\n  \"server_stats\": ", MessageJson(r.stats), "\n}\n");
  return j;
}

std::string ReportText(const RunReport& r) {
  std::vector<double> latencies;
  int ok = 0, resends = 0, duplicates = 0;
  for (const CommandRecord& c : r.commands) {
    if (!c.answered) continue;
    latencies.push_back(c.latency_ms);
    ok += c.reply.code() == 0;
    resends += std::max(0, c.writes - 1);
    duplicates += c.reply.duplicate();
  }
  const WatcherCounts& w = r.watch;
  std::string t = absl::StrCat("session ", r.session.id(), " (", r.session.scene_name(), ")",
                               r.closed ? ", closed" : "", "\n");
  absl::StrAppendFormat(&t,
                        "commands: %d sent, %d ok, %d answered, %d resent, %d duplicate answers, "
                        "%d reconnects; latency median %.3f ms, p99 %.3f ms\n",
                        r.commands.size(), ok, latencies.size(), resends, duplicates, r.reconnects,
                        Percentile(latencies, 0.5), Percentile(latencies, 0.99));
  absl::StrAppendFormat(&t,
                        "frames: %d received (%d keyframes), %d skipped, %.1f frames/s, "
                        "%d bytes (%d of them fields); without fields %.1f %% of raw float32 "
                        "positions; %d written\n",
                        w.frames, w.keyframes, w.skipped,
                        w.seconds > 0 ? (w.frames - 1) / w.seconds : 0.0, w.bytes,
                        w.field_bytes,
                        w.raw_float32_bytes > 0
                            ? 100.0 * (w.bytes - w.field_bytes) / w.raw_float32_bytes
                            : 0.0,
                        w.frames_written);
  absl::StrAppendFormat(&t, "server: step %d, step time median %.3f ms, p99 %.3f ms\n",
                        r.stats.step(), r.stats.step_ms_median(), r.stats.step_ms_p99());
  if (r.checked) {
    absl::StrAppendFormat(&t, "check at step %d: max error %.3g %.3g %.3g m, %s\n", r.check_step,
                          r.check_max_error[0], r.check_max_error[1], r.check_max_error[2],
                          r.check_within_bound ? "within the bound" : "OUTSIDE the bound");
  }
  return t;
}

}  // namespace dynsolid::client
