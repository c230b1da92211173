#include "common/process_stats.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <exception>
#include <limits>

#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

namespace neurosim::common {

namespace {
std::string proc_file(pid_t pid, const char* name) {
  return (pid == 0 ? std::string("/proc/self/") : "/proc/" + std::to_string(pid) + "/") + name;
}
}  // namespace

long resident_kib(pid_t pid) {
  std::ifstream in(proc_file(pid, "status"));
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

double cpu_seconds(pid_t pid) {
  std::ifstream in(proc_file(pid, "stat"));
  const std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Fields after the command name (which may hold spaces) in parentheses: state is field 3,
  // utime 14, stime 15 (clock ticks).
  const auto p = s.rfind(')');
  if (p == std::string::npos || p + 2 > s.size()) return -1;
  std::istringstream is(s.substr(p + 2));
  std::string f;
  unsigned long long ut = 0, st = 0;
  for (int i = 3; i <= 15; ++i) {
    if (!(is >> f)) return -1;
    if (i == 14) ut = std::stoull(f);
    if (i == 15) st = std::stoull(f);
  }
  return static_cast<double>(ut + st) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

namespace {

// "Key:   123 kB" in a /proc file, in bytes; -1 if absent.
double proc_kb_field(const std::string& file, const std::string& key) {
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0) return 1024.0 * std::stod(line.substr(key.size()));
  return -1;
}

// A cgroup v2 file of this process's group holding one number ("max": none); -1 if absent.
double cgroup_value(const std::string& name) {
  std::ifstream cg("/proc/self/cgroup");
  std::string line, path;
  while (std::getline(cg, line))
    if (line.rfind("0::", 0) == 0) path = line.substr(3);
  if (path.empty()) return -1;
  std::ifstream in("/sys/fs/cgroup" + path + "/" + name);
  std::string v;
  if (!(in >> v) || v == "max") return -1;
  try {
    return std::stod(v);
  } catch (const std::exception&) {
    return -1;
  }
}

}  // namespace

double memory_available_bytes(const char** source) {
  double best = std::numeric_limits<double>::infinity();
  const char* from = "unknown";
  auto consider = [&](double v, const char* what) {
    if (v >= 0 && v < best) {
      best = v;
      from = what;
    }
  };
  consider(proc_kb_field("/proc/meminfo", "MemAvailable:"), "MemAvailable");
  rlimit as{};
  if (getrlimit(RLIMIT_AS, &as) == 0 && as.rlim_cur != RLIM_INFINITY) {
    const double vm = proc_kb_field("/proc/self/status", "VmSize:");
    consider(std::max(0.0, static_cast<double>(as.rlim_cur) - std::max(vm, 0.0)), "RLIMIT_AS");
  }
  const double cg_max = cgroup_value("memory.max");
  if (cg_max >= 0)
    consider(std::max(0.0, cg_max - std::max(cgroup_value("memory.current"), 0.0)),
             "cgroup memory.max");
  if (source != nullptr) *source = from;
  return best;
}

}  // namespace neurosim::common
