// LoadWatch: a load phase's result or error comes back (std::bad_alloc named by the phase); a
// stop flag or the load-time limit ends the process at once, naming the phase.
#include "common/load_watch.hpp"

#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace neurosim::common {
namespace {

using neurosim::testing::message_of;

TEST(LoadWatch, ResultsAndErrorsComeBackOutOfMemoryNamed) {
  LoadWatch watch(LoadWatchDef{"prog", 60.0});
  EXPECT_EQ(watch.run("adding", [] { return 2 + 3; }), 5);
  EXPECT_EQ(message_of([&] { watch.run("reading x", []() -> int { throw std::runtime_error("x: bad"); }); }),
            "x: bad");
  EXPECT_EQ(message_of([&] {
              watch.run("building the simulation of s.scene", []() -> int { throw std::bad_alloc(); });
            }),
            "out of memory while building the simulation of s.scene");
}

// A load of 30 s under a limit of 0.2 s.
void load_too_long() {
  LoadWatch watch(LoadWatchDef{"prog", 0.2});
  watch.run("loading the scene s.scene", [] {
    std::this_thread::sleep_for(std::chrono::seconds(30));
    return 0;
  });
}

// A load during which the stop flag is set, as the signal handler would.
void load_stopped() {
  static std::atomic<bool> stop{false};
  LoadWatchDef d;
  d.program = "prog";
  d.stop = &stop;
  d.on_stop = "exiting without serving";
  LoadWatch watch(d);
  watch.run("meshing", [] {
    stop.store(true);
    std::this_thread::sleep_for(std::chrono::seconds(30));
    return 0;
  });
}

TEST(LoadWatchDeathTest, TheLimitEndsALoadThatTakesLonger) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(load_too_long(),
      ::testing::ExitedWithCode(1),
      "prog: error: the load took longer than 0.2 s \\(--load-timeout\\) while loading the scene "
      "s.scene: exiting");
}

TEST(LoadWatchDeathTest, AStopEndsTheLoadNamingThePhase) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(load_stopped(), ::testing::ExitedWithCode(0), "prog: signal received while meshing: exiting without serving");
}

}  // namespace
}  // namespace neurosim::common
