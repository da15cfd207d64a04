// The benchmarks' line naming the machine a figure came from.
#pragma once

#include <cstdio>
#include <string>

namespace dynsolid::bench {

// "model name" of /proc/cpuinfo, and whether it has AVX-512 (the build
// targets AVX2 either way).
inline std::string CpuName() {
  std::FILE* f = std::fopen("/proc/cpuinfo", "r");
  if (f == nullptr) return "unknown CPU";
  std::string name = "unknown CPU";
  bool avx512 = false;
  char line[4096];
  while (std::fgets(line, sizeof line, f) != nullptr) {
    const std::string l(line);
    if (name == "unknown CPU" && l.rfind("model name", 0) == 0) {
      const size_t colon = l.find(':');
      if (colon != std::string::npos) name = l.substr(colon + 2, l.size() - colon - 3);
    }
    if (l.rfind("flags", 0) == 0 && l.find(" avx512f") != std::string::npos) avx512 = true;
  }
  std::fclose(f);
  return name + (avx512 ? " (AVX-512)" : " (no AVX-512)");
}

}  // namespace dynsolid::bench
