// LoopMetrics: the period quantiles and maximum of known ticks (the first tick has no period),
// deadline misses only beyond 1 ms, the model age's p99 (and none when no model was in use),
// the largest force step (a non-finite step ignored), and the --summary JSON with exactly the
// keys haptic_client/README.md lists.
#include "haptic_client/metrics.hpp"

#include "common/json.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <string>
#include <vector>

namespace neurosim::haptic {
namespace {

TEST(haptic_metrics, PeriodQuantilesMissesAndForceStep) {
  LoopMetrics m;
  m.add_tick(-1.0, 0.0, -1.0, 0.0);  // the first tick: no period yet
  // 986 periods of 1 ms, 14 of 3 ms: p50 in the 1 ms bin, p99 in the 3 ms one.
  for (int k = 0; k < 1000; ++k) {
    const double period = k % 67 == 66 ? 3e-3 : 1e-3;
    const double late = k == 10 ? 1e-3 : (k == 20 ? 1.0001e-3 : (k == 30 ? 2e-3 : 1e-5));
    const double step = k == 500 ? 0.25 : (k == 501 ? std::numeric_limits<double>::quiet_NaN() : 0.01);
    m.add_tick(period, late, -1.0, step);
  }
  const LoopSummary s = m.summary();
  EXPECT_EQ(s.samples, 1001u);
  EXPECT_NEAR(s.period_p50_us, 1000.0, 1.0);  // 1 us bins: the upper edge of the bin
  EXPECT_NEAR(s.period_p99_us, 3000.0, 1.0);
  EXPECT_NEAR(s.period_max_us, 3000.0, 1e-9);
  EXPECT_EQ(s.misses_over_1ms, 2u);  // 1.0001 ms and 2 ms late; exactly 1 ms is not a miss
  EXPECT_EQ(s.model_age_p99_ms, -1.0);
  EXPECT_EQ(s.max_force_step_n, 0.25);
}

TEST(haptic_metrics, ModelAgeP99) {
  LoopMetrics m;
  for (int k = 0; k < 100; ++k) m.add_tick(1e-3, 0.0, k < 97 ? 0.005 : 0.040, 0.0);
  const LoopSummary s = m.summary();
  EXPECT_NEAR(s.model_age_p99_ms, 40.0, 0.011);  // 10 us bins
}

TEST(haptic_metrics, SummaryJsonHasExactlyTheListedKeys) {
  LoopMetrics m;
  m.add_tick(1e-3, 0.0, -1.0, 0.5);
  common::Json j = common::Json::parse(summary_json(m.summary()));
  const std::vector<std::string> keys = {"period_p50_us",    "period_p99_us",  "period_max_us",
                                         "misses_over_1ms",  "model_age_p99_ms",
                                         "max_force_step_n", "samples"};
  ASSERT_EQ(j.size(), keys.size());
  for (const auto& k : keys) EXPECT_TRUE(j.contains(k)) << k;
  EXPECT_TRUE(j["model_age_p99_ms"].is_null());  // no model was ever in use
  EXPECT_EQ(j["samples"].get<int>(), 1);
  EXPECT_EQ(j["max_force_step_n"].get<double>(), 0.5);

  m.add_tick(1e-3, 0.0, 0.002, 0.0);
  j = common::Json::parse(summary_json(m.summary()));
  ASSERT_TRUE(j["model_age_p99_ms"].is_number());
  EXPECT_NEAR(j["model_age_p99_ms"].get<double>(), 2.0, 0.011);
}

}  // namespace
}  // namespace neurosim::haptic
