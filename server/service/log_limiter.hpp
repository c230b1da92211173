// Rate limit of log lines: at most N lines per second per cause; the first line of a cause in a
// new second is preceded by a summary of what the last one left out ("suppressed K lines"), so
// a stranger sending garbage cannot flood the log. One thread (the DDS thread) uses it.
#pragma once

#include <cstdint>
#include <map>
#include <string>

namespace neurosim::service {

class LogLimiter {
 public:
  explicit LogLimiter(int lines_per_second = 5);  // >= 1
  // Whether a line of `cause` may be logged at now_ns (monotonic). When it may and the cause's
  // previous window suppressed lines, *summary gets "suppressed K '<cause>' lines in the last
  // second" (else it is cleared).
  bool allow(const std::string& cause, std::int64_t now_ns, std::string* summary);
  std::uint64_t suppressed_total() const { return suppressed_total_; }

 private:
  struct Window {
    std::int64_t start_ns{0};
    int lines{0};
    std::uint64_t suppressed{0};
  };
  int per_second_;
  std::map<std::string, Window> windows_;  // one per cause: a fixed set named in server.cpp
  std::uint64_t suppressed_total_{0};
};

}  // namespace neurosim::service
