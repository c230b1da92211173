// Checks each incoming ToolState before it may reach the physics (bad input from a station):
// non-finite or unusable values and jumps faster than the tool's maximum speed are rejected,
// and the station keeps its last good pose.
#pragma once

#include <cstdint>

struct neurosim_ToolState;

namespace neurosim::service {

enum class Verdict { Accepted, NonFinite, Jump };

const char* to_string(Verdict v);

class ToolFilter {
 public:
  // max_speed_m_per_s > 0 (unit m/s). slack_s: time added to the sample interval before the
  // speed test (unit s) so timing jitter of one device period is not taken for a jump.
  explicit ToolFilter(double max_speed_m_per_s = 2.0, double slack_s = 2e-3);

  // Non-finite position/orientation/velocity or a zero quaternion → NonFinite; a move from the
  // last accepted position longer than max_speed * (dt + slack) → Jump, where dt is the
  // difference of source_time_ns (taken as 0 when it does not increase). The first finite
  // sample is accepted. Only accepted samples become the reference for the next test.
  Verdict check(const neurosim_ToolState& s);
  void reset();
  double max_speed_m_per_s() const { return max_speed_; }

 private:
  double max_speed_;
  double slack_s_;
  bool have_last_{false};
  double last_m_[3]{0, 0, 0};
  std::int64_t last_time_ns_{0};
};

}  // namespace neurosim::service
