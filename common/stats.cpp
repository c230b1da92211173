#include "common/stats.hpp"

#include <stdexcept>

namespace neurosim::common {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  return percentile_in_place(v.begin(), v.end(), p);
}

Percentiles percentiles(std::vector<double> v) {
  Percentiles r;
  r.count = v.size();
  if (v.empty()) return r;
  r.max = *std::max_element(v.begin(), v.end());
  r.p99 = percentile_in_place(v.begin(), v.end(), 0.99);
  r.p50 = percentile_in_place(v.begin(), v.end(), 0.5);
  return r;
}

Histogram::Histogram(double bin_width, std::size_t bins) : width_(bin_width), bins_(bins, 0) {
  if (!(bin_width > 0) || bins == 0)
    throw std::invalid_argument("Histogram: bin width must be > 0 and bins >= 1");
}

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
  const std::uint64_t rank = percentile_index(static_cast<std::size_t>(n_), p) + 1;
  std::uint64_t acc = 0;
  for (std::size_t i = 0; i < bins_.size(); ++i) {
    acc += bins_[i];
    if (acc >= rank) return std::min(max_, width_ * static_cast<double>(i + 1));
  }
  return max_;
}

}  // namespace neurosim::common
