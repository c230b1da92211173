#include "common/process_stats.hpp"

#include <unistd.h>

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

}  // namespace neurosim::common
