#include "haptic_client/metrics.hpp"

#include "common/json.hpp"

#include <algorithm>
#include <cmath>

namespace neurosim::haptic {

// 1 us bins up to 200 ms; 10 us bins up to 10 s.
LoopMetrics::LoopMetrics() : period_us_(1.0, 200000), model_age_ms_(0.01, 1000000) {}

void LoopMetrics::add_tick(double period_s, double lateness_s, double model_age_s,
                           double force_step_n) {
  ++samples_;
  if (period_s >= 0) period_us_.add(period_s * 1e6);
  if (lateness_s > 1e-3) ++misses_;
  if (model_age_s >= 0) model_age_ms_.add(model_age_s * 1e3);
  if (std::isfinite(force_step_n)) max_step_ = std::max(max_step_, force_step_n);
}

LoopSummary LoopMetrics::summary() const {
  LoopSummary s;
  s.period_p50_us = period_us_.quantile(0.5);
  s.period_p99_us = period_us_.quantile(0.99);
  s.period_max_us = period_us_.max();
  s.misses_over_1ms = misses_;
  s.model_age_p99_ms = model_age_ms_.count() > 0 ? model_age_ms_.quantile(0.99) : -1;
  s.max_force_step_n = max_step_;
  s.samples = samples_;
  return s;
}

namespace {

common::Json to_json(const LoopSummary& s) {
  common::Json j;
  j["period_p50_us"] = s.period_p50_us;
  j["period_p99_us"] = s.period_p99_us;
  j["period_max_us"] = s.period_max_us;
  j["misses_over_1ms"] = s.misses_over_1ms;
  j["model_age_p99_ms"] = s.model_age_p99_ms < 0 ? common::Json() : common::Json(s.model_age_p99_ms);
  j["max_force_step_n"] = s.max_force_step_n;
  j["samples"] = s.samples;
  return j;
}

}  // namespace

std::string summary_json(const LoopSummary& s) { return common::to_text(to_json(s)); }

void write_summary_json(const std::string& file, const LoopSummary& s) {
  common::write_json(file, to_json(s));
}

}  // namespace neurosim::haptic
