// Checks each incoming ToolState before it may reach the physics (bad input from a station):
// non-finite or unusable values, a tip outside the scene's workspace, a source time in the
// future, sequence numbers that do not increase, more samples than the station's rate allows,
// and jumps faster than the tool's maximum speed are rejected; the station keeps its last good
// pose. Times of the speed and rate checks are the server's RECEIVE times (monotonic clock when
// the sample was taken), never the sample's own source_time_ns.
#pragma once

#include <cstdint>
#include <limits>

struct neurosim_ToolState;

namespace neurosim::service {

// Why a sample is rejected; each is a SimStatus counter (samples_rejected_<cause>).
enum class Verdict { Accepted, NonFinite, Workspace, Time, Sequence, Rate, Jump };

const char* to_string(Verdict v);

// Axis-aligned box, unit m. The default is unbounded.
struct Workspace {
  double min_m[3]{-std::numeric_limits<double>::max(), -std::numeric_limits<double>::max(),
                  -std::numeric_limits<double>::max()};
  double max_m[3]{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  bool contains(const double p[3]) const;
};

// Tool tips further than this outside the scene's meshes are rejected (unit m): the live
// server's default (--workspace-margin) and neurosim-replay's.
inline constexpr double kDefaultWorkspaceMarginM = 0.5;

// The workspace of a scene: the box of its meshes' rest vertices (add each), enlarged by a
// margin. What the live server and neurosim-replay filter tool tips with.
class WorkspaceBounds {
 public:
  void add(const double p_m[3]);
  // The box enlarged by margin_m (>= 0, unit m) on every side; no vertex added: the margin
  // around the origin.
  Workspace enlarged(double margin_m) const;

 private:
  Workspace box_{};
  bool empty_{true};
};

struct ToolFilterDef {
  double max_speed_m_per_s{2.0};  // > 0, unit m/s
  // Added to the receive interval before the speed test (unit s), so jitter of one device
  // period (a sample delayed, the next on time) is not taken for a jump.
  double slack_s{2e-3};
  Workspace workspace{};          // the tip must stay inside (scene bounding box + margin)
  double max_future_s{1.0};       // source_time_ns at most this far ahead of receive, unit s
  // Token bucket: on average at most max_rate_hz samples per second with bursts of rate_burst;
  // the excess is rejected (Rate). <= 0 Hz: no rate limit. The bucket refills by the advance of
  // the newest source time seen (its high-water mark), which the Time check holds within
  // max_future_s of the server's wall clock: a writer gains at most that once (capped by the
  // burst), then no more than the clock; and samples a stall of the server's own receive thread
  // (a loaded machine) delivers at once still carry their station's spacing, so they are not
  // taken for a flood (over receive times they were, past the burst). The burst covers what a
  // legitimate station sends after a stall of its machine: the haptic client writes up to 100
  // missed ticks back to back before it re-anchors its clock. The limit is there against floods
  // (their average), and 200 samples once cost the server nothing.
  double max_rate_hz{2000.0};
  double rate_burst{200.0};
};

// When a sample was taken: the server's monotonic and wall (Unix epoch, dds_time) clocks, ns.
struct ReceiveTime {
  std::int64_t monotonic_ns{0};
  std::int64_t wall_ns{0};
};

class ToolFilter {
 public:
  ToolFilter() : ToolFilter(ToolFilterDef{}) {}
  explicit ToolFilter(const ToolFilterDef& def);  // throws std::invalid_argument for bad limits

  // In this order: NonFinite (NaN/inf anywhere, or a quaternion that is zero: normalised after
  // scaling by its largest |component|, so 1e200 components are fine); Workspace; Time (source
  // time > receive wall time + max_future_s); Sequence (not above the last accepted one); Rate;
  // Jump (move from the last accepted position longer than max_speed * (receive interval +
  // slack)). The first sample after construction / reset() passes Sequence and Jump (it is
  // still bounded by the workspace). Only accepted samples become the reference. On acceptance
  // unit_q (if not null) gets the normalised quaternion.
  Verdict check(const neurosim_ToolState& s, const ReceiveTime& at, double unit_q[4] = nullptr);
  // A new writer (a station that restarted): forget the last sample, sequence and rate.
  void reset();
  const ToolFilterDef& def() const { return def_; }

 private:
  ToolFilterDef def_;
  bool have_last_{false};
  double last_m_[3]{0, 0, 0};
  std::int64_t last_receive_ns_{0};
  std::uint64_t last_sequence_{0};
  double tokens_{0};
  std::int64_t source_high_ns_{0};  // the newest source time seen by the rate check, unit ns
  bool have_tokens_{false};
};

// q / |q| computed without overflow or underflow (scaled by max |q_i| first). Returns false (q
// left unusable) when q has a non-finite component or is zero.
bool normalise_quaternion(const double q[4], double out[4]);

}  // namespace neurosim::service
