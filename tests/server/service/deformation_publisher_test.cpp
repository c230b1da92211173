// DeformationPublisher on a loopback DDS participant of the test's own: no viewer, no solve; a
// viewer gets FULL frames of every mesh from the field thread; the strain is measured only for
// frames solved for a viewer.
#include "server/service/deformation_publisher.hpp"

#include "tests/server/service/service_parts_fixtures.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

namespace {

using namespace neurosim::service;
namespace wire = neurosim::wire;
using neurosim::service::testing::PoisonSimulation;

// A topic prefix unique to this test and process.
std::string prefix() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string("dp_") + info->name() + "_" + std::to_string(::getpid()) + "_";
}

TEST(service_deformation_publisher, NoViewerNoSolveNoFrame) {
  PoisonSimulation sim;
  wire::Participant pp;
  DeformationPublisher d(sim, pp, prefix(), 30, nullptr);
  d.start(nullptr, nullptr);
  for (int i = 0; i < 10; ++i) d.tick(static_cast<std::uint64_t>(i + 1), 0);
  ASSERT_TRUE(d.wait_idle(10000));
  EXPECT_EQ(d.counters().full_field_solves.load(), 0u);
  EXPECT_EQ(d.counters().frames.load(), 0u);
  EXPECT_EQ(d.take_max_strain(), -1.0) << "no viewer: no field, no strain";
  d.stop();
}

TEST(service_deformation_publisher, AViewerGetsAFullFrameOfEveryMeshFromTheFieldThread) {
  PoisonSimulation sim;
  wire::Participant pp;
  const std::string p = prefix();
  DeformationPublisher d(sim, pp, p, 30, nullptr);
  wire::Topic<neurosim_Deformation> topic(pp, wire::topic_name<neurosim_Deformation>(p));
  wire::Reader<neurosim_Deformation> viewer(pp, topic);
  std::thread::id field_thread;
  d.start([&] { field_thread = std::this_thread::get_id(); }, nullptr);
  // Matching is asynchronous: tick until a frame went out (bounded).
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::uint64_t step = 0;
  while (d.counters().frames.load() == 0 && std::chrono::steady_clock::now() < until) {
    d.tick(++step, 0);
    ASSERT_TRUE(d.wait_idle(10000));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_GE(d.counters().frames.load(), 1u) << "no frame within 20 s of a matched viewer";
  EXPECT_EQ(d.counters().frames.load(), d.counters().full_field_solves.load());
  EXPECT_NE(field_thread, std::this_thread::get_id()) << "fields are solved on the field thread";
  bool full = false;
  const auto until2 = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!full && std::chrono::steady_clock::now() < until2) {
    for (const auto& rx : viewer.take())
      if (rx.valid()) {
        EXPECT_STREQ(rx.data.mesh_id, "block");
        EXPECT_EQ(rx.data.vertex_count, 4u);
        full = full || rx.data.encoding == neurosim_ENCODING_FULL;
      }
    if (!full) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_TRUE(full) << "the first frame after a viewer matched is FULL";
  // Strain: asked for, measured by the next frame (zero displacement: zero strain).
  (void)d.take_max_strain();
  d.tick(++step, 0);
  ASSERT_TRUE(d.wait_idle(10000));
  EXPECT_EQ(d.take_max_strain(), 0.0);
  d.stop();
}

}  // namespace
