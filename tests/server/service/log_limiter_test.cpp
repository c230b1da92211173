// The log limiter: at most N lines per second per cause, then a summary of what it left out.
#include "server/service/log_limiter.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace {
constexpr std::int64_t kMs = 1000000;
}  // namespace

TEST(service_log_limiter, AtMostNLinesPerSecondPerCauseThenASummary) {
  neurosim::service::LogLimiter lim(3);
  std::string summary;
  int allowed = 0;
  for (int i = 0; i < 100; ++i) allowed += lim.allow("identity", i * kMs, &summary);
  EXPECT_EQ(allowed, 3);
  EXPECT_TRUE(lim.allow("workspace", 0, &summary)) << "causes are limited separately";
  EXPECT_TRUE(lim.allow("identity", 1000 * kMs, &summary));
  EXPECT_NE(summary.find("suppressed 97 'identity' lines"), std::string::npos) << summary;
  EXPECT_EQ(lim.suppressed_total(), 97u);
  EXPECT_THROW(neurosim::service::LogLimiter(0), std::invalid_argument);
}
