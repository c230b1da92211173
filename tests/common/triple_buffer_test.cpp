// The newest-value triple buffer: newest wins, freshness is reported once, and across two
// threads the consumer never sees a torn value or one older than a value it already saw.
#include "common/triple_buffer.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <thread>

using neurosim::common::TripleBuffer;

namespace {

// A sample as the server's step thread takes it from the DDS thread.
struct PoseSample {
  std::uint64_t sequence{0};
  std::int64_t source_time_ns{0};
  double position_m[3]{0, 0, 0};
  double orientation[4]{1, 0, 0, 0};
  int tool{0};
};

}  // namespace

TEST(common_triple_buffer, NewestWinsAndConsumeReportsFreshness) {
  TripleBuffer<int> b;
  EXPECT_FALSE(b.consume());
  b.publish(1);
  b.publish(2);
  b.publish(3);
  ASSERT_TRUE(b.consume());
  EXPECT_EQ(b.newest(), 3);
  EXPECT_FALSE(b.consume());
  EXPECT_EQ(b.newest(), 3);
  b.publish(4);
  ASSERT_TRUE(b.consume());
  EXPECT_EQ(b.newest(), 4);
}

TEST(common_triple_buffer, TakeCopiesOnlyFreshValues) {
  TripleBuffer<int> b;
  int v = -1;
  EXPECT_FALSE(b.take(v));
  EXPECT_EQ(v, -1) << "nothing copied when nothing is fresh";
  b.publish(7);
  b.publish(8);
  ASSERT_TRUE(b.take(v));
  EXPECT_EQ(v, 8);
  EXPECT_FALSE(b.take(v));
  EXPECT_EQ(b.newest(), 8);
}

// Producer and consumer on two threads (consume/newest): the consumer never sees a torn sample
// or a sample older than one it already saw.
TEST(common_triple_buffer, TwoThreadsNoTearingNoGoingBack) {
  TripleBuffer<PoseSample> b;
  constexpr std::uint64_t kN = 200000;
  std::atomic<bool> done{false};
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= kN; ++i) {
      PoseSample p;
      p.sequence = i;
      for (double& x : p.position_m) x = static_cast<double>(i);
      for (double& q : p.orientation) q = static_cast<double>(i);
      b.publish(p);
    }
    done = true;
  });
  std::uint64_t last = 0, seen = 0;
  for (;;) {
    const bool finished = done.load();
    if (!b.consume()) {
      if (finished) break;  // everything published before `done` has been seen
      continue;
    }
    const PoseSample& p = b.newest();
    ASSERT_GT(p.sequence, last);
    for (double x : p.position_m) ASSERT_EQ(x, static_cast<double>(p.sequence));
    for (double q : p.orientation) ASSERT_EQ(q, static_cast<double>(p.sequence));
    last = p.sequence;
    ++seen;
  }
  producer.join();
  EXPECT_EQ(last, kN) << "the newest sample must arrive";
  EXPECT_GT(seen, 0u);
}

// The same through take(): whole newest values, never torn or older.
TEST(common_triple_buffer, TakeHandsOverWholeNewestValues) {
  // Producer writes (i, i, i, ...) fast; the consumer must never see a torn or older value.
  struct V {
    std::uint64_t a[8];
  };
  TripleBuffer<V> slot;
  constexpr std::uint64_t kN = 200000;
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= kN; ++i) {
      V v;
      for (auto& x : v.a) x = i;
      slot.publish(v);
    }
  });
  std::uint64_t last = 0, taken = 0;
  V v{};
  while (last < kN) {
    if (!slot.take(v)) continue;
    for (auto x : v.a) ASSERT_EQ(x, v.a[0]) << "torn value";
    ASSERT_GT(v.a[0], last) << "older or repeated value";
    last = v.a[0];
    ++taken;
  }
  producer.join();
  EXPECT_GT(taken, 0u);
  EXPECT_FALSE(slot.take(v)) << "nothing new after the last value";
}
