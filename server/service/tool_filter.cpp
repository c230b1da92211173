#include "server/service/tool_filter.hpp"

#include "idl/wire/types.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::service {

const char* to_string(Verdict v) {
  switch (v) {
    case Verdict::Accepted: return "accepted";
    case Verdict::NonFinite: return "non-finite";
    case Verdict::Jump: return "jump";
  }
  return "unknown";
}

ToolFilter::ToolFilter(double max_speed_m_per_s, double slack_s)
    : max_speed_(max_speed_m_per_s), slack_s_(slack_s) {
  if (!(std::isfinite(max_speed_m_per_s) && max_speed_m_per_s > 0))
    throw std::invalid_argument("ToolFilter: max_speed_m_per_s " +
                                std::to_string(max_speed_m_per_s) + " is not finite and > 0");
  if (!(std::isfinite(slack_s) && slack_s >= 0))
    throw std::invalid_argument("ToolFilter: slack_s " + std::to_string(slack_s) +
                                " is not finite and >= 0");
}

void ToolFilter::reset() { have_last_ = false; }

Verdict ToolFilter::check(const neurosim_ToolState& s) {
  double q2 = 0;
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(s.position_m[i]) || !std::isfinite(s.velocity_m_per_s[i]))
      return Verdict::NonFinite;
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(s.orientation[i])) return Verdict::NonFinite;
    q2 += s.orientation[i] * s.orientation[i];
  }
  // A quaternion that cannot be normalised gives no tool axis.
  if (!(q2 > 1e-12)) return Verdict::NonFinite;
  if (have_last_) {
    double d2 = 0;
    for (int i = 0; i < 3; ++i) {
      const double d = s.position_m[i] - last_m_[i];
      d2 += d * d;
    }
    const double dt_s =
        s.source_time_ns > last_time_ns_ ? 1e-9 * static_cast<double>(s.source_time_ns - last_time_ns_)
                                         : 0.0;
    const double allowed_m = max_speed_ * (dt_s + slack_s_);
    if (d2 > allowed_m * allowed_m) return Verdict::Jump;
  }
  have_last_ = true;
  for (int i = 0; i < 3; ++i) last_m_[i] = s.position_m[i];
  last_time_ns_ = s.source_time_ns;
  return Verdict::Accepted;
}

}  // namespace neurosim::service
