// The step is State only: once warmed up (contact columns cached, workspace sized) it must not
// allocate. Counts global operator new calls around step().
#include "server/interaction/simulation.hpp"

#include "interaction_fixtures.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  ++g_allocations;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace neurosim::interaction {
namespace {

void expect_warm_step_does_not_allocate(const testing::SceneSpec& spec) {
  auto sim = Simulation::build(testing::make_scene(spec), "test.scene");
  std::vector<ToolPose> poses(2);
  auto set = [&](double d0, double d1) {
    poses[0].tip_m = Vec3(0.1 + spec.tip_radius_m - d0, 0.05, 0.05);
    poses[0].axis = Vec3::UnitX();
    poses[1].tip_m = Vec3(0.05, 0.1 + spec.tip_radius_m - d1, 0.06);
    poses[1].axis = Vec3::UnitY();
  };
  std::vector<ToolContact> contacts;
  StepStats stats;
  // Warm-up over the same path: columns of every touched node get cached (this allocates, which
  // also shows the counter works).
  const long at_build = g_allocations.load();
  for (int k = 0; k <= 10; ++k) {
    set(0.0005 * k, 0.0004 * k);
    sim->step(poses, contacts, stats);
  }
  ASSERT_TRUE(contacts[0].in_contact);
  ASSERT_TRUE(contacts[1].in_contact);
  EXPECT_GT(g_allocations.load() - at_build, 0);
  const long before = g_allocations.load();
  for (int k = 10; k >= 0; --k) {
    set(0.0005 * k, 0.0004 * k);
    sim->step(poses, contacts, stats);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

TEST(interaction_allocation, WarmStepDoesNotAllocate) {
  expect_warm_step_does_not_allocate(testing::SceneSpec{});
}

// SLIDING: the sliding rows join the LCP (constant block, factor kept between steps).
TEST(interaction_allocation, WarmSlidingStepDoesNotAllocate) {
  testing::SceneSpec spec;
  spec.sliding = true;
  expect_warm_step_does_not_allocate(spec);
}

}  // namespace
}  // namespace neurosim::interaction
