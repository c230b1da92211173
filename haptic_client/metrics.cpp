#include "haptic_client/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace neurosim::haptic {

Histogram::Histogram(double bin_width, std::size_t bins) : width_(bin_width), bins_(bins, 0) {}

void Histogram::add(double v) {
  if (!std::isfinite(v) || v < 0) v = 0;
  const double b = v / width_;
  const std::size_t i =
      b >= static_cast<double>(bins_.size() - 1) ? bins_.size() - 1 : static_cast<std::size_t>(b);
  ++bins_[i];
  ++n_;
  max_ = std::max(max_, v);
}

double Histogram::quantile(double p) const {
  if (n_ == 0) return 0;
  const auto rank = static_cast<std::uint64_t>(std::ceil(p * static_cast<double>(n_)));
  std::uint64_t acc = 0;
  for (std::size_t i = 0; i < bins_.size(); ++i) {
    acc += bins_[i];
    if (acc >= std::max<std::uint64_t>(rank, 1))
      return std::min(max_, width_ * static_cast<double>(i + 1));
  }
  return max_;
}

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

std::string summary_json(const LoopSummary& s) {
  std::ostringstream o;
  o.precision(9);
  o << "{\n  \"period_p50_us\": " << s.period_p50_us
    << ",\n  \"period_p99_us\": " << s.period_p99_us
    << ",\n  \"period_max_us\": " << s.period_max_us
    << ",\n  \"misses_over_1ms\": " << s.misses_over_1ms << ",\n  \"model_age_p99_ms\": ";
  if (s.model_age_p99_ms < 0)
    o << "null";
  else
    o << s.model_age_p99_ms;
  o << ",\n  \"max_force_step_n\": " << s.max_force_step_n << ",\n  \"samples\": " << s.samples
    << "\n}\n";
  return o.str();
}

void write_summary_json(const std::string& file, const LoopSummary& s) {
  std::ofstream f(file);
  if (!f) throw std::runtime_error(file + ": cannot open for writing the summary");
  f << summary_json(s);
  f.close();
  if (!f) throw std::runtime_error(file + ": write failed");
}

}  // namespace neurosim::haptic
