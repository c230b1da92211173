// The ToolState filter: non-finite values, workspace, future times, sequence, rate, jumps beyond
// the maximum speed at receive times.
#include "idl/wire/types.hpp"
#include "server/service/tool_filter.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using neurosim::service::ReceiveTime;
using neurosim::service::ToolFilter;
using neurosim::service::ToolFilterDef;
using neurosim::service::Verdict;

namespace {

neurosim_ToolState tool(double x, std::int64_t t_ns) {
  neurosim_ToolState s{};
  s.position_m[0] = x;
  s.orientation[0] = 1;
  s.source_time_ns = t_ns;
  return s;
}

}  // namespace

constexpr std::int64_t kMs = 1000000;
constexpr std::int64_t kWall0 = 1700000000000000000;  // Unix epoch ns

// Received at monotonic t_ns, wall clock kWall0 + t_ns.
ReceiveTime at(std::int64_t t_ns) { return ReceiveTime{t_ns, kWall0 + t_ns}; }

ToolFilterDef def(double vmax = 2.0, double slack = 2e-3) {
  ToolFilterDef d;
  d.max_speed_m_per_s = vmax;
  d.slack_s = slack;
  return d;
}

// A sample sent at t (sequence = t in ms + 1, source time = the wall clock then).
neurosim_ToolState at_ms(double x, std::int64_t t_ns) {
  auto s = tool(x, kWall0 + t_ns);
  s.sequence_number = static_cast<std::uint64_t>(t_ns / kMs) + 1;
  return s;
}

TEST(service_tool_filter, RejectsNonFiniteAnywhere) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  ToolFilter f(def());
  EXPECT_EQ(f.check(at_ms(0.1, 0), at(0)), Verdict::Accepted);
  for (int field = 0; field < 10; ++field) {
    auto s = at_ms(0.1, kMs);
    double* v = field < 3 ? &s.position_m[field] : field < 6 ? &s.velocity_m_per_s[field - 3] : &s.orientation[field - 6];
    *v = field % 2 ? nan : -inf;
    EXPECT_EQ(f.check(s, at(kMs)), Verdict::NonFinite) << "field " << field;
  }
  auto zero_q = at_ms(0.1, kMs);
  zero_q.orientation[0] = 0;
  EXPECT_EQ(f.check(zero_q, at(kMs)), Verdict::NonFinite);
  EXPECT_EQ(f.check(at_ms(0.1, 2 * kMs), at(2 * kMs)), Verdict::Accepted);
}

TEST(service_tool_filter, JumpIsMeasuredFromTheLastGoodPoseAtReceiveTimes) {
  ToolFilter f(def(2.0, 0.0));  // 2 m/s, no slack: 1 ms allows 2 mm
  EXPECT_EQ(f.check(at_ms(0.0, 0), at(0)), Verdict::Accepted);
  EXPECT_EQ(f.check(at_ms(0.0019, 1 * kMs), at(1 * kMs)), Verdict::Accepted);
  EXPECT_EQ(f.check(at_ms(0.0100, 2 * kMs), at(2 * kMs)), Verdict::Jump);  // 8.1 mm in 1 ms
  // Still measured from 1.9 mm at 1 ms: 3.9 mm in 2 ms is allowed.
  EXPECT_EQ(f.check(at_ms(0.0058, 3 * kMs), at(3 * kMs)), Verdict::Accepted);
  // Received at the same instant: no motion allowed at all.
  auto s = at_ms(0.0059, 4 * kMs);
  EXPECT_EQ(f.check(s, at(3 * kMs)), Verdict::Jump);
  f.reset();
  EXPECT_EQ(f.check(at_ms(0.5, 5 * kMs), at(5 * kMs)), Verdict::Accepted) << "after reset the next sample is the first";
}

TEST(service_tool_filter, FutureSourceTimeNeitherPassesNorWidensTheSpeedCheck) {
  ToolFilter f(def(2.0, 0.0));
  EXPECT_EQ(f.check(at_ms(0.0, 0), at(0)), Verdict::Accepted);
  // Stamped 10 s later but received 1 ms later: 1 m is a jump (receive time counts), and the
  // stamp itself is more than 1 s ahead of the server's clock.
  auto s = at_ms(1.0, kMs);
  s.source_time_ns = kWall0 + 10000 * kMs;
  EXPECT_EQ(f.check(s, at(kMs)), Verdict::Time);
  s.source_time_ns = kWall0 + 500 * kMs;  // 0.5 s ahead: allowed clock skew, but still a jump
  EXPECT_EQ(f.check(s, at(kMs)), Verdict::Jump);
  EXPECT_EQ(f.check(at_ms(0.001, 2 * kMs), at(2 * kMs)), Verdict::Accepted);
}

TEST(service_tool_filter, TheFirstSampleIsBoundedByTheWorkspace) {
  ToolFilterDef d = def();
  for (int i = 0; i < 3; ++i) {
    d.workspace.min_m[i] = -0.5;
    d.workspace.max_m[i] = 0.6;
  }
  ToolFilter f(d);
  EXPECT_EQ(f.check(at_ms(1e308, 0), at(0)), Verdict::Workspace);
  EXPECT_EQ(f.check(at_ms(-1e30, kMs), at(kMs)), Verdict::Workspace);
  EXPECT_EQ(f.check(at_ms(0.61, 2 * kMs), at(2 * kMs)), Verdict::Workspace);
  EXPECT_EQ(f.check(at_ms(0.59, 3 * kMs), at(3 * kMs)), Verdict::Accepted);
}

TEST(service_tool_filter, HugeQuaternionsAreNormalisedTinyOrZeroOnesRefused) {
  ToolFilter f(def());
  auto s = at_ms(0.0, 0);
  s.orientation[0] = 1e300;
  s.orientation[3] = 1e300;  // squared norm overflows to inf
  double q[4] = {0, 0, 0, 0};
  ASSERT_EQ(f.check(s, at(0), q), Verdict::Accepted);
  EXPECT_NEAR(q[0], std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(q[3], std::sqrt(0.5), 1e-15);
  EXPECT_EQ(q[1], 0.0);
  auto tiny = at_ms(0.0, kMs);
  tiny.orientation[0] = 1e-300;  // squared norm underflows to 0: still a direction
  ASSERT_EQ(f.check(tiny, at(kMs), q), Verdict::Accepted);
  EXPECT_DOUBLE_EQ(q[0], 1.0);
  auto zero = at_ms(0.0, 2 * kMs);
  zero.orientation[0] = 0;
  EXPECT_EQ(f.check(zero, at(2 * kMs), q), Verdict::NonFinite);
}

TEST(service_tool_filter, SequenceMustIncreaseUntilANewWriter) {
  ToolFilter f(def());
  auto s = at_ms(0.0, 0);
  s.sequence_number = 100;
  EXPECT_EQ(f.check(s, at(0)), Verdict::Accepted);
  s.sequence_number = 99;
  s.source_time_ns += kMs;
  EXPECT_EQ(f.check(s, at(kMs)), Verdict::Sequence);
  s.sequence_number = 100;
  EXPECT_EQ(f.check(s, at(2 * kMs)), Verdict::Sequence) << "a repeated number is not newer";
  s.sequence_number = 101;
  EXPECT_EQ(f.check(s, at(3 * kMs)), Verdict::Accepted);
  f.reset();  // the station restarted (new writer): it starts over at 1
  s.sequence_number = 1;
  EXPECT_EQ(f.check(s, at(4 * kMs)), Verdict::Accepted);
}

TEST(service_tool_filter, RateAboveTheLimitIsRejectedA1kHzStationNever) {
  ToolFilterDef d = def();
  d.max_rate_hz = 2000;
  d.rate_burst = 20;
  ToolFilter fast(d), steady(d);
  int rate = 0;
  for (std::int64_t k = 0; k < 2000; ++k) {  // 20 kHz for 0.1 s, each sample stamped when sent
    auto s = at_ms(0.0, k * 50000);
    s.sequence_number = static_cast<std::uint64_t>(k + 1);
    rate += fast.check(s, at(k * 50000)) == Verdict::Rate;
  }
  EXPECT_GT(rate, 1700);  // ~200 + 20 of 2000 pass
  EXPECT_LT(rate, 1800);
  // The same flood with one source time (a writer that does not stamp its samples): the bucket
  // never refills, the burst alone passes.
  ToolFilter stale(d);
  rate = 0;
  for (std::int64_t k = 0; k < 2000; ++k) {
    auto s = at_ms(0.0, 0);
    s.sequence_number = static_cast<std::uint64_t>(k + 1);
    rate += stale.check(s, at(k * 50000)) == Verdict::Rate;
  }
  EXPECT_EQ(rate, 2000 - 20);
  for (std::int64_t k = 0; k < 2000; ++k) {  // 1 kHz with +-0.4 ms jitter
    const std::int64_t t = k * kMs + ((k % 2) ? 400000 : -400000);
    auto s = at_ms(0.0, k * kMs);
    ASSERT_EQ(steady.check(s, at(t + kMs)), Verdict::Accepted) << k;
  }
}

// The haptic client (haptic_client/loop.cpp) catches up missed ticks back to back after a
// stall of its machine, up to 100 of them before it re-anchors its clock: a legitimate burst
// the default limit must accept, while a flood is still held to the average rate.
TEST(service_tool_filter, TheDefaultRateLimitAcceptsTheClientsCatchUpBurstNotAFlood) {
  const ToolFilterDef d;
  ToolFilter station(d), flood(d);
  std::int64_t t = 0;
  std::uint64_t seq = 0;
  auto send = [&](ToolFilter& f, std::int64_t receive_ns) {
    auto s = at_ms(0.0, receive_ns);
    s.sequence_number = ++seq;
    return f.check(s, at(receive_ns));
  };
  for (int k = 0; k < 1000; ++k, t += kMs) ASSERT_EQ(send(station, t), Verdict::Accepted) << k;
  t += 100 * kMs;  // the station's machine stalled for 100 ms: no sample
  for (int k = 0; k < 100; ++k)  // then its 100 missed ticks back to back, 10 us apart
    ASSERT_EQ(send(station, t + k * 10000), Verdict::Accepted) << "catch-up sample " << k;
  t += kMs;
  for (int k = 0; k < 1000; ++k, t += kMs) ASSERT_EQ(send(station, t), Verdict::Accepted) << k;
  // 20 kHz for 1 s: about max_rate_hz + rate_burst pass, the rest is rejected.
  seq = 0;
  int passed = 0;
  for (std::int64_t k = 0; k < 20000; ++k) passed += send(flood, k * 50000) == Verdict::Accepted;
  EXPECT_LE(passed, static_cast<int>(d.max_rate_hz + d.rate_burst) + 1);
  EXPECT_GE(passed, static_cast<int>(d.max_rate_hz) - 1);
}

// A stall of the server's own receive thread (a loaded machine) delivers a 1 kHz station's
// samples at once: they carry their 1 ms spacing in their source times, so however long the
// stall, none is taken for a flood. Forged source times (jumping to the Time check's limit and
// back) refill the bucket by their high-water mark's advance only: once, then with the clock.
TEST(service_tool_filter, AServerStallsBurstPassesForgedSourceTimesGainNothing) {
  const ToolFilterDef d;
  ToolFilter station(d), forger(d);
  std::uint64_t seq = 0;
  std::int64_t t = 0;
  for (int k = 0; k < 100; ++k, t += kMs) {
    auto s = at_ms(0.0, t);
    s.sequence_number = ++seq;
    ASSERT_EQ(station.check(s, at(t)), Verdict::Accepted) << k;
  }
  // 1000 samples sent 1 ms apart, received within 10 ms after a 1 s stall of the server.
  const std::int64_t stall_end = t + 1000 * kMs;
  for (int k = 0; k < 1000; ++k, t += kMs) {
    auto s = at_ms(0.0, t);
    s.sequence_number = ++seq;
    ASSERT_EQ(station.check(s, at(stall_end + k * 10000)), Verdict::Accepted) << "burst sample " << k;
  }
  // A flood at 20 kHz for 1 s whose source times alternate between the Time check's limit
  // (0.99 s ahead of the wall clock) and 5 s behind it: about max_rate_hz + rate_burst pass.
  seq = 0;
  int passed = 0;
  for (std::int64_t k = 0; k < 20000; ++k) {
    const std::int64_t r = k * 50000;
    auto s = at_ms(0.0, (k % 2) ? r + 990 * kMs : r - 5000 * kMs);
    s.sequence_number = ++seq;
    passed += forger.check(s, at(r)) == Verdict::Accepted;
  }
  std::printf("forged source times: %d of 20000 passed\n", passed);
  EXPECT_LE(passed, static_cast<int>(d.max_rate_hz + 2 * d.rate_burst) + 1);
  EXPECT_GE(passed, static_cast<int>(d.max_rate_hz) - 1);
}

TEST(service_tool_filter, RefusesBadLimits) {
  EXPECT_THROW(ToolFilter(def(0.0)), std::invalid_argument);
  EXPECT_THROW(ToolFilter(def(std::numeric_limits<double>::quiet_NaN())), std::invalid_argument);
  EXPECT_THROW(ToolFilter(def(1.0, -1.0)), std::invalid_argument);
  ToolFilterDef d;
  d.workspace.min_m[1] = 1;
  d.workspace.max_m[1] = 0;
  EXPECT_THROW(ToolFilter{d}, std::invalid_argument);
}
