#include "clients/load/report.h"

#include <algorithm>
#include <cstdio>

#include <unistd.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/lib/stats.h"

namespace dynsolid::load {
namespace {

double Ms(std::chrono::steady_clock::duration d) {
  return std::chrono::duration<double, std::milli>(d).count();
}

Percentiles Summarize(std::vector<double> v) {
  Percentiles p;
  p.count = static_cast<int64_t>(v.size());
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  p.p50 = client::Percentile(v, 0.5);
  p.p99 = client::Percentile(v, 0.99);
  p.p999 = client::Percentile(v, 0.999);
  p.max = v.back();
  return p;
}

// Whether a command never builds a solid on the server: not a paint, an
// edit, an unfix, an undo or a redo (those may build for tens to hundreds
// of ms, and their command is visible only after).
bool BuildsNothing(const Command& c) {
  switch (c.kind_case()) {
    case Command::kPaintMaterial:
    case Command::kEdit:
    case Command::kUnfix:
    case Command::kUndo:
    case Command::kRedo:
      return false;
    default:
      return true;
  }
}

}  // namespace

std::string CodeName(int code) {
  static const char* kNames[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT",
                                 "DEADLINE_EXCEEDED", "NOT_FOUND", "ALREADY_EXISTS",
                                 "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
                                 "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL",
                                 "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  return code >= 0 && code <= 16 ? kNames[code] : absl::StrCat("CODE_", code);
}

std::string KindName(const Command& c) {
  const google::protobuf::FieldDescriptor* f =
      Command::descriptor()->FindFieldByNumber(c.kind_case());
  return f != nullptr ? f->name() : "none";
}

void ClientFigures(const Options& o, std::vector<ClientResult>& results,
                   const std::vector<ClientResult>& fault_results,
                   const std::vector<client::CommandRecord>& burst_records, double run_seconds,
                   Report& rep) {
  std::vector<double> ack, visible, visible_no_build;
  std::map<std::string, std::vector<double>> visible_by_kind;
  double fps_sum = 0;
  for (int i = 0; i < o.clients; ++i) {
    ClientResult& r = results[i];
    for (const std::string& p : r.problems) rep.problems.push_back(p);
    std::sort(r.frames.begin(), r.frames.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    for (const client::CommandRecord& rec : r.records) {
      ++rep.sent;
      rep.resends += rec.writes - 1;
      rep.rate_limited += rec.rate_limited;
      if (!rec.answered) continue;
      ++rep.codes[CodeName(rec.reply.code())];
      if (rec.reply.applied_step() < 0) continue;
      ++rep.acknowledged;
      (rec.reply.code() == 0 ? rep.applied : rep.rejected) += 1;
      const std::string kind = KindName(rec.command);
      if (rec.reply.code() != 0 && o.verbose) {
        // As LoadRun::Log writes its progress.
        std::fprintf(stderr, "dynsolid-load: %s\n",
                     absl::StrCat("refused ", kind, ": ", rec.reply.message()).c_str());
      }
      if (!rec.reply.duplicate()) {
        Report::Hold& h = rep.hold[kind];
        ++h.count;
        h.total_ms += rec.reply.hold_ms();
        h.max_ms = std::max(h.max_ms, rec.reply.hold_ms());
      }
      ack.push_back(rec.latency_ms);
      // Visible: the first frame at or after the applied step received
      // after the command was sent; for applied commands only (a refused
      // one changed nothing there is to see: its ack is its answer).
      if (rec.reply.code() != 0) continue;
      for (const auto& [step, at] : r.frames) {
        if (at >= rec.sent && step >= rec.reply.applied_step()) {
          const double ms = Ms(at - rec.sent);
          visible.push_back(ms);
          visible_by_kind[kind].push_back(ms);
          if (BuildsNothing(rec.command)) visible_no_build.push_back(ms);
          break;
        }
      }
    }
    rep.frames += r.watch.frames;
    rep.frames_skipped += r.watch.skipped;
    rep.reconnects += r.reconnects + r.watch.reconnects;
    if (r.watch.seconds > 0) fps_sum += (r.watch.frames - 1) / r.watch.seconds;
  }
  for (const ClientResult& f : fault_results) {
    for (const std::string& p : f.problems) rep.problems.push_back(p);
    for (const auto& [k, v] : f.fault_codes) rep.codes[k] += v;
  }
  for (const client::CommandRecord& rec : burst_records) {
    rep.rate_limited += rec.rate_limited;
    if (rec.answered) ++rep.codes[absl::StrCat("burst: ", CodeName(rec.reply.code()))];
  }
  rep.frames_per_second = o.clients > 0 ? fps_sum / o.clients : 0;
  rep.commands_per_second = run_seconds > 0 ? rep.acknowledged / run_seconds : 0;
  rep.ack_ms = Summarize(ack);
  rep.visible_ms = Summarize(visible);
  rep.visible_no_build_ms = Summarize(visible_no_build);
  for (auto& [kind, v] : visible_by_kind) rep.visible_by_kind_ms[kind] = Summarize(v);
}

void ServerFigures(const SessionStats& before, const SessionStats& after, const CpuWindow& cpu_window,
                   int restarts, double run_seconds, Report& rep) {
  rep.loaded_steps_per_second =
      run_seconds > 0 ? (after.step() - before.step()) / run_seconds : 0;
  rep.step_ms_median = after.step_ms_median();
  rep.step_ms_p99 = after.step_ms_p99();
  rep.steps_dropped = after.steps_dropped() - (restarts > 0 ? 0 : before.steps_dropped());
  rep.overruns = after.overruns() - (restarts > 0 ? 0 : before.overruns());
  rep.time_step = after.time_step();
  rep.restarts = restarts;
  double cpu = 0;
  for (const auto& s : rep.server_samples) cpu += s[1];
  rep.server_cpu_percent = rep.server_samples.empty() ? 0 : cpu / rep.server_samples.size();
  if (!rep.server_samples.empty()) rep.server_rss_end_kb = static_cast<int64_t>(rep.server_samples.back()[2]);
  const CpuWindow& w = cpu_window;
  rep.busy_cores = BusyCoresBetween(w.tool0, w.tool1);
  rep.cores = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  for (const auto& [name, use] : CpuBetween(w.tool0, w.tool1, w.seconds)) {
    rep.load_tool.Add(use);
  }
  if (restarts == 0 && run_seconds > 0) {
    rep.build_busy_ms_per_s = (after.build_ms_total() - before.build_ms_total()) / run_seconds;
    rep.builds.cpu_ms_per_s = (after.build_cpu_ms_total() - before.build_cpu_ms_total()) / run_seconds;
    rep.builds.wait_ms_per_s =
        (after.build_wait_ms_total() - before.build_wait_ms_total()) / run_seconds;
    rep.builds.runs_per_s = (after.builds() - before.builds()) / run_seconds;
    rep.builds.threads = 1;
  }
  if (w.server_pid > 0 && restarts == 0) {
    for (const auto& [name, use] : CpuBetween(w.server0, w.server1, w.seconds)) {
      const bool own = name == "sim" || name == "encode" || name == "journal";
      rep.server_threads[own ? name : "gRPC and other"].Add(use);
    }
  }
}

std::string ReportJson(const Report& r) {
  auto pct = [](const Percentiles& p) {
    return absl::StrFormat("{\"count\": %d, \"p50\": %.3f, \"p99\": %.3f, \"p999\": %.3f, \"max\": %.3f}",
                           p.count, p.p50, p.p99, p.p999, p.max);
  };
  std::string codes;
  for (const auto& [k, v] : r.codes) absl::StrAppend(&codes, codes.empty() ? "" : ", ", "\"", k, "\": ", v);
  std::string placed;
  for (const auto& [k, v] : r.sessions_per_replica) {
    absl::StrAppend(&placed, placed.empty() ? "" : ", ", "\"", k, "\": ", v);
  }
  std::string hold;
  for (const auto& [k, h] : r.hold) {
    absl::StrAppend(&hold, hold.empty() ? "" : ", ",
                    absl::StrFormat("\"%s\": {\"count\": %d, \"total_ms\": %.1f, \"max_ms\": %.2f}",
                                    k, h.count, h.total_ms, h.max_ms));
  }
  std::string by_kind;
  for (const auto& [k, p] : r.visible_by_kind_ms) {
    absl::StrAppend(&by_kind, by_kind.empty() ? "" : ", ", "\"", k, "\": ", pct(p));
  }
  std::string samples;
  for (const auto& s : r.server_samples) {
    absl::StrAppend(&samples, samples.empty() ? "" : ", ", absl::StrFormat("[%.3f, %.1f, %.0f]", s[0], s[1], s[2]));
  }
  auto use = [](const CpuUse& u) {
    return absl::StrFormat(
        "{\"threads\": %d, \"cpu_ms_per_s\": %.1f, \"wait_ms_per_s\": %.1f, \"runs_per_s\": %.0f}",
        u.threads, u.cpu_ms_per_s, u.wait_ms_per_s, u.runs_per_s);
  };
  std::string threads;
  for (const auto& [name, u] : r.server_threads) {
    absl::StrAppend(&threads, threads.empty() ? "" : ", ", "\"", name, "\": ", use(u));
  }
  std::string problems;
  for (const std::string& p : r.problems) {
    std::string q = p;
    for (size_t k = 0; (k = q.find('"', k)) != std::string::npos; k += 2) q.replace(k, 1, "\\\"");
    absl::StrAppend(&problems, problems.empty() ? "" : ", ", "\"", q, "\"");
  }
  const Options& o = r.options;
  return absl::StrCat(
      "{\n  \"scene\": \"", o.scene, "\", \"clients\": ", o.clients, ", \"shared\": ",
      o.shared ? "true" : "false", ", \"seconds\": ", o.seconds, ", \"rate\": ", o.rate,
      ", \"seed\": ", o.seed, ", \"edits\": ", o.edits ? "true" : "false",
      ",\n  \"faults\": {\"disconnect\": ", o.faults.disconnect ? "true" : "false",
      ", \"stop_reading\": ", o.faults.stop_reading ? "true" : "false",
      ", \"malformed\": ", o.faults.malformed ? "true" : "false",
      ", \"burst\": ", o.faults.burst ? "true" : "false",
      ", \"restart\": ", o.faults.restart ? "true" : "false", "}",
      ",\n  \"sent\": ", r.sent, ", \"acknowledged\": ", r.acknowledged, ", \"applied\": ", r.applied,
      ", \"rejected\": ", r.rejected, ", \"commands_per_second\": ", absl::StrFormat("%.1f", r.commands_per_second),
      ",\n  \"ack_ms\": ", pct(r.ack_ms), ",\n  \"visible_ms\": ", pct(r.visible_ms),
      ",\n  \"visible_no_build_ms\": ", pct(r.visible_no_build_ms),
      ",\n  \"visible_by_kind_ms\": {", by_kind, "}",
      ",\n  \"codes\": {", codes, "}", ",\n  \"hold\": {", hold, "}",
      ",\n  \"frames\": ", r.frames, ", \"frames_skipped\": ", r.frames_skipped,
      ", \"frames_per_second\": ", absl::StrFormat("%.1f", r.frames_per_second),
      ", \"reconnects\": ", r.reconnects, ", \"resends\": ", r.resends, ", \"rate_limited\": ", r.rate_limited,
      ",\n  \"time_step\": ", r.time_step,
      ", \"unloaded_steps_per_second\": ", absl::StrFormat("%.1f", r.unloaded_steps_per_second),
      ", \"loaded_steps_per_second\": ", absl::StrFormat("%.1f", r.loaded_steps_per_second),
      ", \"step_ms_median\": ", absl::StrFormat("%.3f", r.step_ms_median),
      ", \"step_ms_p99\": ", absl::StrFormat("%.3f", r.step_ms_p99),
      ", \"steps_dropped\": ", r.steps_dropped, ", \"overruns\": ", r.overruns,
      ",\n  \"server_cpu_percent\": ", absl::StrFormat("%.1f", r.server_cpu_percent),
      ", \"server_rss_max_kb\": ", r.server_rss_max_kb, ", \"server_rss_end_kb\": ", r.server_rss_end_kb,
      ", \"restarts\": ", r.restarts, ", \"sessions_per_replica\": {", placed, "}",
      ",\n  \"server_samples\": [", samples, "]",
      ",\n  \"server_threads\": {", threads, "}, \"load_tool\": ", use(r.load_tool),
      ", \"busy_cores\": ", absl::StrFormat("%.2f", r.busy_cores), ", \"cores\": ", r.cores,
      ",\n  \"builds\": ", use(r.builds),
      ", \"build_busy_ms_per_s\": ", absl::StrFormat("%.1f", r.build_busy_ms_per_s),
      ",\n  \"verified\": ", r.verified ? "true" : "false", ", \"problems\": [", problems, "]",
      ",\n  \"wall_seconds\": ", absl::StrFormat("%.1f", r.wall_seconds), "\n}\n");
}

std::string ReportMarkdown(const Report& r) {
  const Options& o = r.options;
  std::string faults;
  for (const auto& [on, name] : {std::pair{o.faults.disconnect, "disconnect"},
                                 std::pair{o.faults.stop_reading, "stop_reading"},
                                 std::pair{o.faults.malformed, "malformed"},
                                 std::pair{o.faults.burst, "burst"},
                                 std::pair{o.faults.restart, "restart"}}) {
    if (on) absl::StrAppend(&faults, faults.empty() ? "" : ", ", name);
  }
  std::string out = absl::StrFormat(
      "| scene | clients | sessions | faults | commands/s | ack p50 / p99 / p99.9 / max (ms) | "
      "visible p50 / p99 / p99.9 / max (ms) | visible p50 / p99 of commands that build nothing "
      "(ms) | steps/s unloaded -> loaded (h = %g s) | step ms "
      "median / p99 | dropped | frames/s per watcher | skipped | server CPU %% / RSS max (MB) | "
      "lost, duplicated, reordered |\n"
      "| --- | ---: | --- | --- | ---: | --- | --- | --- | --- | --- | ---: | ---: | ---: | --- | "
      "--- |\n",
      r.time_step);
  absl::StrAppend(
      &out,
      absl::StrFormat("| %s | %d | %s | %s | %.1f | %.2f / %.2f / %.2f / %.2f | %.2f / %.2f / %.2f / "
                      "%.2f | %.2f / %.2f | %.0f -> %.0f | %.3f / %.3f | %d | %.1f | %d | %.0f / "
                      "%.0f | %s |\n",
                      o.scene, o.clients, o.shared ? "one shared" : "one each",
                      faults.empty() ? "none" : faults, r.commands_per_second, r.ack_ms.p50,
                      r.ack_ms.p99, r.ack_ms.p999, r.ack_ms.max, r.visible_ms.p50, r.visible_ms.p99,
                      r.visible_ms.p999, r.visible_ms.max, r.visible_no_build_ms.p50,
                      r.visible_no_build_ms.p99, r.unloaded_steps_per_second,
                      r.loaded_steps_per_second, r.step_ms_median, r.step_ms_p99, r.steps_dropped,
                      r.frames_per_second, r.frames_skipped, r.server_cpu_percent,
                      r.server_rss_max_kb / 1024.0,
                      !r.verified ? "not checked" : r.problems.empty() ? "none" : "**see problems**"));
  if (r.cores > 0) {
    // Where the CPU went: a second table, after a blank line.
    auto cell = [](const CpuUse& u) {
      const double mean_us = u.runs_per_s > 0 ? 1e3 * u.wait_ms_per_s / u.runs_per_s : 0;
      return absl::StrFormat("%.0f / %.0f, %.0f us (%d)", u.cpu_ms_per_s, u.wait_ms_per_s, mean_us,
                             u.threads);
    };
    std::string head = "| busy cores | dynsolid-load (clients) | server builds: busy / CPU / wait (builds/s) |",
                rule = "| ---: | --- | --- |";
    std::string row = absl::StrFormat("| %.2f of %d | %s | %.0f / %.0f / %.0f (%.1f) |", r.busy_cores,
                                      r.cores, cell(r.load_tool), r.build_busy_ms_per_s,
                                      r.builds.cpu_ms_per_s, r.builds.wait_ms_per_s,
                                      r.builds.runs_per_s);
    for (const auto& [name, u] : r.server_threads) {
      absl::StrAppend(&head, " server ", name, " |");
      absl::StrAppend(&rule, " --- |");
      absl::StrAppend(&row, " ", cell(u), " |");
    }
    absl::StrAppend(&out, "\nCPU per second of the run: ms on a CPU / ms ready but waiting for one, "
                          "the mean wait each time it was woken (threads):\n\n", head, "\n", rule,
                    "\n", row, "\n");
  }
  return out;
}

}  // namespace dynsolid::load
