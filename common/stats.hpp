// Percentiles and a fixed-bin histogram. One definition everywhere: the p-percentile of n values
// is the nearest-rank one, the smallest value with at least ceil(p * n) values (and at least
// one) at or below it; p = 0.5 is the median, p = 1 the maximum.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <limits>
#include <vector>

namespace neurosim::common {

// 0-based index of the nearest-rank p-percentile among n >= 1 sorted values.
inline std::size_t percentile_index(std::size_t n, double p) {
  const double rank = std::ceil(p * static_cast<double>(n));
  if (!(rank > 1)) return 0;  // also p <= 0 and NaN
  return std::min(n, static_cast<std::size_t>(rank)) - 1;
}

// p-percentile of [first, last), which it reorders (std::nth_element: no allocation). The range
// must not be empty.
template <class RandomIt>
auto percentile_in_place(RandomIt first, RandomIt last, double p) {
  const auto n = static_cast<std::size_t>(std::distance(first, last));
  const RandomIt k = first + static_cast<std::ptrdiff_t>(percentile_index(n, p));
  std::nth_element(first, k, last);
  return *k;
}

// p-percentile of v (a copy: v is left alone); NaN when v is empty.
double percentile(std::vector<double> v, double p);

// Median, 99th percentile and maximum of a sample set (NaN when empty).
struct Percentiles {
  std::size_t count = 0;
  double p50 = std::numeric_limits<double>::quiet_NaN();
  double p99 = std::numeric_limits<double>::quiet_NaN();
  double max = std::numeric_limits<double>::quiet_NaN();
};
Percentiles percentiles(std::vector<double> v);

// Histogram with fixed bins [0, bin_width * bins); larger values go to the last bin, negative and
// non-finite ones to the first; the maximum is kept exactly. Allocated once: add() allocates
// nothing.
class Histogram {
 public:
  Histogram(double bin_width, std::size_t bins);
  void add(double v);
  std::uint64_t count() const { return n_; }
  double max() const { return max_; }
  // Upper edge of the bin holding the p-percentile (at most max()); 0 when empty.
  double quantile(double p) const;

 private:
  double width_;
  std::vector<std::uint32_t> bins_;
  std::uint64_t n_ = 0;
  double max_ = 0;
};

}  // namespace neurosim::common
