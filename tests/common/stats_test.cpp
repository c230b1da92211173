// Nearest-rank percentiles and the fixed-bin histogram use the same definition.
#include "common/stats.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

namespace nc = neurosim::common;

TEST(common_stats, NearestRankPercentile) {
  std::vector<double> v(100);
  std::iota(v.begin(), v.end(), 1.0);  // 1 .. 100
  std::reverse(v.begin(), v.end());
  EXPECT_EQ(nc::percentile(v, 0.5), 50.0);
  EXPECT_EQ(nc::percentile(v, 0.99), 99.0);
  EXPECT_EQ(nc::percentile(v, 1.0), 100.0);
  EXPECT_EQ(nc::percentile(v, 0.0), 1.0);
  EXPECT_EQ(nc::percentile(v, 0.001), 1.0);
  EXPECT_EQ(v.front(), 100.0) << "percentile works on a copy";
  EXPECT_EQ(nc::percentile({7.0}, 0.99), 7.0);
  EXPECT_TRUE(std::isnan(nc::percentile({}, 0.5)));
  EXPECT_EQ(nc::percentile({3.0, 1.0, 2.0}, 0.5), 2.0);

  std::vector<float> f{5, 4, 3, 2, 1};
  EXPECT_EQ(nc::percentile_in_place(f.begin(), f.end(), 0.5), 3.0F);
  EXPECT_EQ(nc::percentile_index(5, 0.5), 2u);
  EXPECT_EQ(nc::percentile_index(5, 2.0), 4u);
}

TEST(common_stats, PercentilesSummary) {
  std::vector<double> v(1000);
  std::iota(v.begin(), v.end(), 1.0);
  const nc::Percentiles p = nc::percentiles(v);
  EXPECT_EQ(p.count, 1000u);
  EXPECT_EQ(p.p50, 500.0);
  EXPECT_EQ(p.p99, 990.0);
  EXPECT_EQ(p.max, 1000.0);
  const nc::Percentiles e = nc::percentiles({});
  EXPECT_EQ(e.count, 0u);
  EXPECT_TRUE(std::isnan(e.p50));
}

TEST(common_stats, HistogramQuantileMatchesPercentileToBinWidth) {
  nc::Histogram h(1.0, 1000);
  EXPECT_EQ(h.quantile(0.5), 0.0) << "empty";
  std::vector<double> v;
  for (int i = 0; i < 500; ++i) {
    const double x = 0.37 * i + 0.1;
    h.add(x);
    v.push_back(x);
  }
  EXPECT_EQ(h.count(), 500u);
  EXPECT_DOUBLE_EQ(h.max(), 0.37 * 499 + 0.1);
  for (double p : {0.5, 0.9, 0.99}) {
    const double exact = nc::percentile(v, p);
    EXPECT_GE(h.quantile(p), exact);
    EXPECT_LE(h.quantile(p), exact + 1.0);
  }
  EXPECT_EQ(h.quantile(1.0), h.max());
  h.add(1e9);  // last bin, max exact
  h.add(-5);   // first bin
  h.add(std::nan(""));
  EXPECT_EQ(h.max(), 1e9);
  EXPECT_EQ(h.count(), 503u);
  EXPECT_THROW(nc::Histogram(0.0, 10), std::invalid_argument);
}
