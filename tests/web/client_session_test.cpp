// ClientSession: protocol order, keyframes before deltas the client cannot decode, frames of
// another generation skipped, a failed send ends the session.
#include "web/client_session.hpp"

#include <gtest/gtest.h>

#include <thread>

namespace web = neurosim::web;

namespace {

web::MessagePtr msg(const std::string& text) { return web::text_message(text); }

web::FramePtr full(std::uint16_t mesh, std::uint32_t gen, std::uint64_t serial) {
  auto f = std::make_shared<web::Frame>();
  f->mesh_index = mesh;
  f->generation = gen;
  f->full = true;
  f->full_serial = serial;
  f->message.binary = true;
  f->message.bytes = "F" + std::to_string(serial);
  return f;
}

web::FramePtr delta(const web::FramePtr& base, int n) {
  auto f = std::make_shared<web::Frame>();
  f->mesh_index = base->mesh_index;
  f->generation = base->generation;
  f->full = false;
  f->full_serial = base->full_serial;
  f->base = base;
  f->message.binary = true;
  f->message.bytes = "D" + std::to_string(base->full_serial) + "." + std::to_string(n);
  return f;
}

web::TopologyPtr topology(std::uint32_t gen, std::size_t meshes) {
  auto t = std::make_shared<web::Topology>();
  t->generation = gen;
  t->meshes = meshes;
  t->messages.push_back(msg("T" + std::to_string(gen)));
  for (std::size_t i = 0; i < meshes; ++i) t->messages.push_back(msg("G" + std::to_string(i)));
  return t;
}

struct Recorder {
  std::vector<std::string> sent;
  int fail_after = -1;  // fail the n-th send (0-based), -1 never
  web::ClientSession::Send fn() {
    return [this](const web::Message& m) {
      if (fail_after >= 0 && static_cast<int>(sent.size()) == fail_after) return false;
      sent.push_back(m.bytes);
      return true;
    };
  }
};

}  // namespace

TEST(ClientSession, TopologyStatusStationsThenFrames) {
  auto box = std::make_shared<web::ClientOutbox>(1, "p");
  Recorder r;
  web::ClientSession s(box, r.fn());
  web::ClientOutbox::Pending p;
  p.topology = topology(1, 1);
  p.status = msg("S");
  p.stations = msg("ST");
  p.frames[0] = full(0, 1, 5);
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent, (std::vector<std::string>{"T1", "G0", "S", "ST", "F5"}));
  EXPECT_EQ(box->counters().frames_sent, 1U);
}

TEST(ClientSession, DeltaGoesAfterItsKeyframeOnlyWhenTheClientLacksIt) {
  auto box = std::make_shared<web::ClientOutbox>(1, "p");
  Recorder r;
  web::ClientSession s(box, r.fn());
  const auto f5 = full(0, 1, 5);
  web::ClientOutbox::Pending p;
  p.topology = topology(1, 1);
  p.frames[0] = delta(f5, 1);  // a late joiner: the FULL frame was sent before it came
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent, (std::vector<std::string>{"T1", "G0", "F5", "D5.1"}));
  r.sent.clear();
  p = {};
  p.frames[0] = delta(f5, 2);  // same keyframe: the delta alone
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent, (std::vector<std::string>{"D5.2"}));
  r.sent.clear();
  const auto f6 = full(0, 1, 6);
  p = {};
  p.frames[0] = delta(f6, 1);  // the FULL frame 6 was replaced in the outbox by its delta
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent, (std::vector<std::string>{"F6", "D6.1"}));
  const auto c = box->counters();
  EXPECT_EQ(c.keyframes_sent, 2U);
  EXPECT_EQ(c.frames_sent, 5U);
}

TEST(ClientSession, FramesOfAnotherGenerationOrBeforeTheTopologyAreSkipped) {
  auto box = std::make_shared<web::ClientOutbox>(1, "p");
  Recorder r;
  web::ClientSession s(box, r.fn());
  web::ClientOutbox::Pending p;
  p.frames[0] = full(0, 1, 1);  // no topology yet
  ASSERT_TRUE(s.send(p));
  EXPECT_TRUE(r.sent.empty());
  p = {};
  p.topology = topology(2, 1);
  p.frames[0] = full(0, 1, 2);  // old generation
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent, (std::vector<std::string>{"T2", "G0"}));
  p = {};
  p.frames[3] = full(3, 2, 3);  // no such mesh in this topology
  ASSERT_TRUE(s.send(p));
  EXPECT_EQ(r.sent.size(), 2U);
  EXPECT_EQ(box->counters().frames_dropped, 3U);
}

TEST(ClientSession, FailedSendEndsTheSession) {
  auto box = std::make_shared<web::ClientOutbox>(1, "p");
  Recorder r;
  r.fail_after = 1;
  web::ClientSession s(box, r.fn());
  box->put_topology(topology(1, 1));
  s.run(std::chrono::milliseconds(10));  // returns by itself: the second send fails
  EXPECT_EQ(r.sent, (std::vector<std::string>{"T1"}));
  EXPECT_TRUE(box->counters().failed);
}

TEST(ClientSession, RunEndsWhenTheOutboxCloses) {
  auto box = std::make_shared<web::ClientOutbox>(1, "p");
  Recorder r;
  web::ClientSession s(box, r.fn());
  std::thread t([&] { s.run(std::chrono::milliseconds(10)); });
  box->put_status(msg("S"));
  for (int i = 0; i < 400 && box->counters().messages_sent == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  box->close();
  t.join();
  EXPECT_EQ(r.sent, (std::vector<std::string>{"S"}));
}
