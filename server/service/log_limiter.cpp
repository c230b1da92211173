#include "server/service/log_limiter.hpp"

#include <stdexcept>

namespace neurosim::service {

LogLimiter::LogLimiter(int lines_per_second) : per_second_(lines_per_second) {
  if (lines_per_second < 1)
    throw std::invalid_argument("log limit: " + std::to_string(lines_per_second) +
                                " lines per second is below 1");
}

bool LogLimiter::allow(const std::string& cause, std::int64_t now_ns, std::string* summary) {
  if (summary != nullptr) summary->clear();
  auto [it, fresh] = windows_.try_emplace(cause);
  Window& w = it->second;
  if (fresh || now_ns - w.start_ns >= 1000000000) {
    if (w.suppressed > 0 && summary != nullptr)
      *summary = "suppressed " + std::to_string(w.suppressed) + " '" + cause +
                 "' lines in the last second";
    w.start_ns = now_ns;
    w.lines = 0;
    w.suppressed = 0;
  }
  if (w.lines < per_second_) {
    ++w.lines;
    return true;
  }
  ++w.suppressed;
  ++suppressed_total_;
  return false;
}

}  // namespace neurosim::service
