#include "clients/load/proc_stats.h"

#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"

namespace dynsolid::load {
namespace {

std::string ReadFirstLine(const std::string& path) {
  std::ifstream f(path);
  std::string line;
  std::getline(f, line);
  return line;
}

}  // namespace

CpuSnapshot TakeCpuSnapshot(pid_t pid) {
  CpuSnapshot s;
  // The machine: "cpu  user nice system idle iowait irq softirq steal ...".
  {
    std::istringstream in(ReadFirstLine("/proc/stat"));
    std::string label;
    in >> label;
    double field = 0, total = 0, idle = 0;
    for (int i = 0; i < 8 && in >> field; ++i) {
      total += field;
      if (i == 3 || i == 4) idle += field;  // idle, iowait
    }
    const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
    s.machine_total_s = total / tick;
    s.machine_busy_s = (total - idle) / tick;
  }
  if (pid <= 0) {
    s.ok = s.machine_total_s > 0;
    return s;
  }
  const std::string dir = absl::StrCat("/proc/", pid, "/task");
  DIR* d = opendir(dir.c_str());
  if (d == nullptr) return s;
  while (const dirent* e = readdir(d)) {
    if (e->d_name[0] == '.') continue;
    const std::string task = absl::StrCat(dir, "/", e->d_name);
    const std::string name = ReadFirstLine(task + "/comm");
    // "on-CPU ns, run-queue wait ns, timeslices".
    std::istringstream in(ReadFirstLine(task + "/schedstat"));
    double run_ns = 0, wait_ns = 0, runs = 0;
    if (name.empty() || !(in >> run_ns >> wait_ns >> runs)) continue;  // it ended meanwhile
    ThreadTime& t = s.by_name[name];
    ++t.threads;
    t.cpu_s += run_ns * 1e-9;
    t.wait_s += wait_ns * 1e-9;
    t.runs += runs;
  }
  closedir(d);
  s.ok = true;
  return s;
}

std::map<std::string, CpuUse> CpuBetween(const CpuSnapshot& a, const CpuSnapshot& b,
                                         double seconds) {
  std::map<std::string, CpuUse> out;
  if (!a.ok || !b.ok || seconds <= 0) return out;
  for (const auto& [name, tb] : b.by_name) {
    ThreadTime ta;
    if (auto it = a.by_name.find(name); it != a.by_name.end()) ta = it->second;
    CpuUse& u = out[name];
    u.threads = tb.threads;
    // Threads that ended take their time with them: never below zero.
    u.cpu_ms_per_s = std::max(0.0, tb.cpu_s - ta.cpu_s) * 1e3 / seconds;
    u.wait_ms_per_s = std::max(0.0, tb.wait_s - ta.wait_s) * 1e3 / seconds;
    u.runs_per_s = std::max(0.0, tb.runs - ta.runs) / seconds;
  }
  return out;
}

double BusyCoresBetween(const CpuSnapshot& a, const CpuSnapshot& b) {
  const double total = b.machine_total_s - a.machine_total_s;
  if (!a.ok || !b.ok || total <= 0) return 0;
  // total counts every core's ticks: busy / total is a fraction of them all.
  return (b.machine_busy_s - a.machine_busy_s) / total * sysconf(_SC_NPROCESSORS_ONLN);
}

}  // namespace dynsolid::load
