#include "server/service/tool_filter.hpp"

#include "idl/wire/types.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::service {

const char* to_string(Verdict v) {
  switch (v) {
    case Verdict::Accepted: return "accepted";
    case Verdict::NonFinite: return "non-finite";
    case Verdict::Workspace: return "workspace";
    case Verdict::Time: return "time";
    case Verdict::Sequence: return "sequence";
    case Verdict::Rate: return "rate";
    case Verdict::Jump: return "jump";
  }
  return "unknown";
}

bool Workspace::contains(const double p[3]) const {
  for (int i = 0; i < 3; ++i)
    if (!(p[i] >= min_m[i] && p[i] <= max_m[i])) return false;
  return true;
}

void WorkspaceBounds::add(const double p_m[3]) {
  for (int i = 0; i < 3; ++i) {
    box_.min_m[i] = empty_ ? p_m[i] : std::min(box_.min_m[i], p_m[i]);
    box_.max_m[i] = empty_ ? p_m[i] : std::max(box_.max_m[i], p_m[i]);
  }
  empty_ = false;
}

Workspace WorkspaceBounds::enlarged(double margin_m) const {
  Workspace w;
  for (int i = 0; i < 3; ++i) {
    w.min_m[i] = (empty_ ? 0.0 : box_.min_m[i]) - margin_m;
    w.max_m[i] = (empty_ ? 0.0 : box_.max_m[i]) + margin_m;
  }
  return w;
}

bool normalise_quaternion(const double q[4], double out[4]) {
  double scale = 0;
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(q[i])) return false;
    scale = std::max(scale, std::abs(q[i]));
  }
  if (!(scale > 0)) return false;  // also catches subnormal-only underflow below
  double n2 = 0;
  for (int i = 0; i < 4; ++i) {
    const double c = q[i] / scale;
    n2 += c * c;
  }
  const double n = std::sqrt(n2);  // in [1, 2]
  for (int i = 0; i < 4; ++i) out[i] = (q[i] / scale) / n;
  return true;
}

namespace {

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("ToolFilter: " + what);
}

}  // namespace

ToolFilter::ToolFilter(const ToolFilterDef& def) : def_(def) {
  require(std::isfinite(def.max_speed_m_per_s) && def.max_speed_m_per_s > 0,
          "max_speed_m_per_s " + std::to_string(def.max_speed_m_per_s) + " is not finite and > 0");
  require(std::isfinite(def.slack_s) && def.slack_s >= 0,
          "slack_s " + std::to_string(def.slack_s) + " is not finite and >= 0");
  require(std::isfinite(def.max_future_s) && def.max_future_s >= 0,
          "max_future_s " + std::to_string(def.max_future_s) + " is not finite and >= 0");
  require(std::isfinite(def.max_rate_hz) && std::isfinite(def.rate_burst) &&
              (def.max_rate_hz <= 0 || def.rate_burst >= 1),
          "max_rate_hz / rate_burst not finite, or a burst below 1");
  for (int i = 0; i < 3; ++i)
    require(!std::isnan(def.workspace.min_m[i]) && !std::isnan(def.workspace.max_m[i]) &&
                def.workspace.min_m[i] <= def.workspace.max_m[i],
            "workspace: min above max (or NaN) on axis " + std::to_string(i));
}

void ToolFilter::reset() {
  have_last_ = false;
  last_sequence_ = 0;
  have_tokens_ = false;
}

Verdict ToolFilter::check(const neurosim_ToolState& s, const ReceiveTime& at, double unit_q[4]) {
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(s.position_m[i]) || !std::isfinite(s.velocity_m_per_s[i]))
      return Verdict::NonFinite;
  double q[4];
  // A quaternion that cannot be normalised gives no tool axis.
  if (!normalise_quaternion(s.orientation, q)) return Verdict::NonFinite;
  if (!def_.workspace.contains(s.position_m)) return Verdict::Workspace;
  const double ahead_s = 1e-9 * (static_cast<double>(s.source_time_ns) - static_cast<double>(at.wall_ns));
  if (ahead_s > def_.max_future_s) return Verdict::Time;
  if (have_last_ && s.sequence_number <= last_sequence_) return Verdict::Sequence;
  if (def_.max_rate_hz > 0) {
    if (!have_tokens_) {
      have_tokens_ = true;
      tokens_ = def_.rate_burst;
      source_high_ns_ = s.source_time_ns;
    } else if (s.source_time_ns > source_high_ns_) {
      // The difference as unsigned: exact for any two int64 with source > high (no overflow).
      const std::uint64_t advance_ns = static_cast<std::uint64_t>(s.source_time_ns) -
                                       static_cast<std::uint64_t>(source_high_ns_);
      tokens_ = std::min(def_.rate_burst, tokens_ + 1e-9 * static_cast<double>(advance_ns) * def_.max_rate_hz);
      source_high_ns_ = s.source_time_ns;
    }
    if (tokens_ < 1.0) return Verdict::Rate;
    tokens_ -= 1.0;
  }
  if (have_last_) {
    double d2 = 0;
    for (int i = 0; i < 3; ++i) {
      const double d = s.position_m[i] - last_m_[i];
      d2 += d * d;
    }
    const double dt_s =
        at.monotonic_ns > last_receive_ns_ ? 1e-9 * static_cast<double>(at.monotonic_ns - last_receive_ns_) : 0.0;
    const double allowed_m = def_.max_speed_m_per_s * (dt_s + def_.slack_s);
    if (d2 > allowed_m * allowed_m) return Verdict::Jump;
  }
  have_last_ = true;
  for (int i = 0; i < 3; ++i) last_m_[i] = s.position_m[i];
  last_receive_ns_ = at.monotonic_ns;
  last_sequence_ = s.sequence_number;
  if (unit_q != nullptr)
    for (int i = 0; i < 4; ++i) unit_q[i] = q[i];
  return Verdict::Accepted;
}

}  // namespace neurosim::service
