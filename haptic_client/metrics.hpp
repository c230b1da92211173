// Loop metrics: period histogram, deadline misses, model age, force step.
// Fixed-size histograms (common::Histogram) allocated once: recording a tick allocates nothing.
#pragma once

#include "common/stats.hpp"

#include <cstdint>
#include <string>

namespace neurosim::haptic {

struct LoopSummary {
  double period_p50_us = 0;
  double period_p99_us = 0;
  double period_max_us = 0;
  std::uint64_t misses_over_1ms = 0;  // ticks that started more than 1 ms after their deadline
  double model_age_p99_ms = -1;       // < 0: no model was ever in use
  double max_force_step_n = 0;        // largest |F(k) - F(k-1)|
  std::uint64_t samples = 0;          // ticks
};

class LoopMetrics {
 public:
  LoopMetrics();
  // period_s: time since the previous tick started (< 0 for the first tick); lateness_s: start
  // minus deadline; model_age_s < 0 when no model is in use.
  void add_tick(double period_s, double lateness_s, double model_age_s, double force_step_n);
  LoopSummary summary() const;

 private:
  common::Histogram period_us_;
  common::Histogram model_age_ms_;
  std::uint64_t misses_ = 0;
  double max_step_ = 0;
  std::uint64_t samples_ = 0;
};

// The summary JSON of --summary, exactly the keys listed in haptic_client/README.md;
// model_age_p99_ms is null when no model was ever in use.
std::string summary_json(const LoopSummary& s);
void write_summary_json(const std::string& file, const LoopSummary& s);

}  // namespace neurosim::haptic
