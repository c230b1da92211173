// ClientOutbox: latest wins per mesh, bounded whatever the producer does, a new topology drops
// frames of the old one, close wakes the sender.
#include "web/client_outbox.hpp"

#include <gtest/gtest.h>

#include <thread>

namespace web = neurosim::web;
using std::chrono::milliseconds;

namespace {

web::FramePtr frame(std::uint16_t mesh, std::uint32_t generation, std::uint64_t serial,
                    bool full = true) {
  auto f = std::make_shared<web::Frame>();
  f->mesh_index = mesh;
  f->generation = generation;
  f->full = full;
  f->full_serial = serial;
  f->message.binary = true;
  f->message.bytes.assign(1000, 'x');
  return f;
}

web::TopologyPtr topology(std::uint32_t generation) {
  auto t = std::make_shared<web::Topology>();
  t->generation = generation;
  t->meshes = 2;
  return t;
}

}  // namespace

TEST(ClientOutbox, LatestFrameWinsPerMesh) {
  web::ClientOutbox box(1, "peer");
  for (std::uint64_t i = 1; i <= 1000; ++i)
    box.put_frame(frame(static_cast<std::uint16_t>(i % 2), 1, i));
  web::ClientOutbox::Pending p;
  ASSERT_TRUE(box.take(p, milliseconds(0)));
  ASSERT_EQ(p.frames.size(), 2U);  // one per mesh, however many were put
  EXPECT_EQ(p.frames.at(0)->full_serial, 1000U);
  EXPECT_EQ(p.frames.at(1)->full_serial, 999U);
  EXPECT_EQ(box.counters().frames_dropped, 998U);
  ASSERT_TRUE(box.take(p, milliseconds(0)));
  EXPECT_TRUE(p.empty());  // taken: nothing left
}

TEST(ClientOutbox, NewTopologyDropsFramesOfTheOldOne) {
  web::ClientOutbox box(1, "peer");
  box.put_frame(frame(0, 1, 1));
  box.put_frame(frame(1, 2, 2));
  box.put_topology(topology(2));
  web::ClientOutbox::Pending p;
  ASSERT_TRUE(box.take(p, milliseconds(0)));
  ASSERT_TRUE(p.topology);
  ASSERT_EQ(p.frames.size(), 1U);
  EXPECT_EQ(p.frames.begin()->second->generation, 2U);
  EXPECT_EQ(box.counters().frames_dropped, 1U);
}

TEST(ClientOutbox, StatusAndStationsLatestWins) {
  web::ClientOutbox box(1, "peer");
  box.put_status(web::text_message("{\"n\":1}"));
  box.put_status(web::text_message("{\"n\":2}"));
  box.put_stations(web::text_message("{\"s\":1}"));
  web::ClientOutbox::Pending p;
  ASSERT_TRUE(box.take(p, milliseconds(0)));
  EXPECT_EQ(p.status->bytes, "{\"n\":2}");
  EXPECT_EQ(p.stations->bytes, "{\"s\":1}");
}

TEST(ClientOutbox, TakeWaitsAndCloseWakesIt) {
  web::ClientOutbox box(1, "peer");
  web::ClientOutbox::Pending p;
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(box.take(p, milliseconds(50)));  // nothing: returns after the timeout, still open
  EXPECT_GE(std::chrono::steady_clock::now() - t0, milliseconds(45));
  EXPECT_TRUE(p.empty());
  std::thread closer([&] {
    std::this_thread::sleep_for(milliseconds(50));
    box.close();
  });
  EXPECT_FALSE(box.take(p, milliseconds(5000)));  // woken by close long before the timeout
  closer.join();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, milliseconds(3000));
  box.put_frame(frame(0, 1, 1));  // ignored once closed
  EXPECT_FALSE(box.take(p, milliseconds(0)));
}

TEST(ClientOutbox, CountsWhatTheSenderReports) {
  web::ClientOutbox box(7, "127.0.0.1:5000");
  box.note_sent(100, true, false);
  box.note_sent(50, true, true);
  box.note_sent(10, false, false);
  box.note_failed();
  const web::ClientCounters c = box.counters();
  EXPECT_EQ(c.id, 7U);
  EXPECT_EQ(c.peer, "127.0.0.1:5000");
  EXPECT_EQ(c.messages_sent, 3U);
  EXPECT_EQ(c.frames_sent, 2U);
  EXPECT_EQ(c.keyframes_sent, 1U);
  EXPECT_EQ(c.bytes_sent, 160U);
  EXPECT_TRUE(c.failed);
}
