// Hub: at most max_clients, a late joiner starts from the current state (topology, status,
// stations, newest frame with its keyframe), a new topology forgets older frames.
#include "web/hub.hpp"

#include <gtest/gtest.h>

namespace web = neurosim::web;
using std::chrono::milliseconds;

namespace {

web::TopologyPtr topology(std::uint32_t gen) {
  auto t = std::make_shared<web::Topology>();
  t->generation = gen;
  t->meshes = 1;
  return t;
}

web::FramePtr frame(std::uint32_t gen, std::uint64_t serial) {
  auto f = std::make_shared<web::Frame>();
  f->generation = gen;
  f->full_serial = serial;
  return f;
}

}  // namespace

TEST(Hub, RefusesBeyondMaxClientsAndTakesOneAgainAfterALeave) {
  web::HubOptions o;
  o.max_clients = 2;
  web::Hub hub(o);
  auto a = hub.join("a"), b = hub.join("b");
  ASSERT_TRUE(a && b);
  EXPECT_FALSE(hub.join("c"));
  EXPECT_EQ(hub.counters().refused, 1U);
  hub.leave(a);
  EXPECT_TRUE(a->closed());
  EXPECT_EQ(hub.clients(), 1U);
  EXPECT_TRUE(hub.join("d"));
  EXPECT_EQ(hub.counters().joined, 3U);
}

TEST(Hub, LateJoinerStartsFromTheCurrentState) {
  web::Hub hub;
  hub.publish_frame(frame(1, 1));  // before any topology: not kept
  hub.publish_topology(topology(1));
  hub.publish_status(web::text_message("S"));
  hub.publish_stations(web::text_message("ST"));
  hub.publish_frame(frame(1, 2));
  hub.publish_frame(frame(1, 3));
  auto c = hub.join("late");
  web::ClientOutbox::Pending p;
  ASSERT_TRUE(c->take(p, milliseconds(0)));
  ASSERT_TRUE(p.topology);
  EXPECT_EQ(p.topology->generation, 1U);
  EXPECT_EQ(p.status->bytes, "S");
  EXPECT_EQ(p.stations->bytes, "ST");
  ASSERT_EQ(p.frames.size(), 1U);
  EXPECT_EQ(p.frames.at(0)->full_serial, 3U);  // the newest only
}

TEST(Hub, NewTopologyForgetsOlderFramesAndReachesEveryClient) {
  web::Hub hub;
  hub.publish_topology(topology(1));
  auto c = hub.join("c");
  hub.publish_frame(frame(1, 1));
  hub.publish_topology(topology(2));
  hub.publish_frame(frame(1, 2));  // a frame of the old generation after the new topology
  web::ClientOutbox::Pending p;
  ASSERT_TRUE(c->take(p, milliseconds(0)));
  EXPECT_EQ(p.topology->generation, 2U);
  EXPECT_TRUE(p.frames.empty());
  auto late = hub.join("late");
  ASSERT_TRUE(late->take(p, milliseconds(0)));
  EXPECT_TRUE(p.frames.empty());
}

TEST(Hub, CloseAllStopsEverySender) {
  web::Hub hub;
  auto a = hub.join("a"), b = hub.join("b");
  hub.close_all();
  EXPECT_TRUE(a->closed());
  EXPECT_TRUE(b->closed());
}
