// timespec <-> ns conversion, clock readings and absolute sleeps.
#include "common/clock.hpp"

#include <gtest/gtest.h>

namespace nc = neurosim::common;

TEST(common_clock, TimespecRoundTrip) {
  for (std::int64_t ns : {0LL, 1LL, 999999999LL, 1000000000LL, 1234567890123LL}) {
    const timespec t = nc::to_timespec(ns);
    EXPECT_GE(t.tv_nsec, 0);
    EXPECT_LT(t.tv_nsec, 1000000000L);
    EXPECT_EQ(nc::to_ns(t), ns);
  }
  const timespec t = nc::to_timespec(2500000001LL);
  EXPECT_EQ(t.tv_sec, 2);
  EXPECT_EQ(t.tv_nsec, 500000001L);
}

TEST(common_clock, SleepUntilReachesTheDeadline) {
  const std::int64_t t0 = nc::monotonic_ns();
  const auto c0 = nc::Clock::now();
  nc::sleep_until_ns(t0 + 20000000);  // 20 ms
  EXPECT_GE(nc::monotonic_ns(), t0 + 20000000);
  EXPECT_GE(nc::seconds_since(c0), 0.019);
  EXPECT_GE(nc::ms_since(c0), 19.0);
  EXPECT_GT(nc::realtime_ns(), 1500000000LL * 1000000000LL) << "after 2017";
  EXPECT_GE(nc::thread_cpu_ms(), 0.0);
}
