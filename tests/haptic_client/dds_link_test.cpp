// DdsLink against a server the test drives by hand (a participant of its own writing exactly the
// ContactModels and SimStatus it chooses, under a topic prefix of its own, loopback): what the
// end-to-end haptic_dds_test cannot pin down, sample by sample. A published pose reaches the
// server with every field and in the station's own partition; gaps in the server's step count
// are counted as skipped models, a restarted server's count is not a gap, and a rejected
// sample is counted; a refusal is reported only when it names this link's own writer, and
// expires when it is older than 2 s; a link without a station id is refused.
#include "common/clock.hpp"
#include "haptic_client/dds_link.hpp"
#include "idl/wire/dds.hpp"
#include "idl/wire/qos.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <functional>
#include <thread>

namespace nh = neurosim::haptic;
namespace wire = neurosim::wire;

namespace {

using neurosim::common::Clock;
using neurosim::common::realtime_ns;
using neurosim::common::seconds_since;

bool eventually(const std::function<bool()>& done, double timeout_s = 10) {
  const auto t0 = Clock::now();
  while (!done()) {
    if (seconds_since(t0) > timeout_s) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

// The server side, driven by the test.
class HandServer {
 public:
  explicit HandServer(const std::string& prefix)
      : tool_topic_(pp_, wire::topic_name<neurosim_ToolState>(prefix)),
        tools(pp_, tool_topic_),
        model_topic_(pp_, wire::topic_name<neurosim_ContactModel>(prefix)),
        models_(pp_, model_topic_),
        status_topic_(pp_, wire::topic_name<neurosim_SimStatus>(prefix)),
        status_(pp_, status_topic_) {
    wire::set_string(st_->server_id, "hand");
  }
  void model(const std::string& station, std::uint64_t server_step, std::uint64_t tool_sequence,
             bool rejected = false) {
    wire::set_string(cm_->station_id, station);
    cm_->server_step = server_step;
    cm_->tool_sequence = tool_sequence;
    cm_->tool_source_time_ns = 1000 + static_cast<std::int64_t>(tool_sequence);
    cm_->tool_sample_rejected = rejected;
    cm_->x0_orientation[0] = 1;
    models_.write(*cm_);
  }
  // A SimStatus whose refused list has one entry (none when station is empty).
  void status(const std::string& station, const std::array<std::uint8_t, 16>& writer,
              neurosim_RefusalReason reason, std::int64_t time_ns) {
    wire::reserve(st_->refused, 1);
    st_->refused._length = station.empty() ? 0 : 1;
    if (!station.empty()) {
      neurosim_StationRefusal& r = st_->refused._buffer[0];
      wire::set_string(r.station_id, station);
      std::memcpy(r.writer_guid, writer.data(), 16);
      r.reason = reason;
      r.time_ns = time_ns;
    }
    status_.write(*st_);
  }
  wire::MatchedPublication writer_of(dds_instance_handle_t h) const {
    return tools.matched_publication(h);
  }

 private:
  wire::Participant pp_;
  wire::Topic<neurosim_ToolState> tool_topic_;

 public:
  wire::Reader<neurosim_ToolState> tools;

 private:
  wire::Topic<neurosim_ContactModel> model_topic_;
  wire::Writer<neurosim_ContactModel> models_;
  wire::Topic<neurosim_SimStatus> status_topic_;
  wire::Writer<neurosim_SimStatus> status_;
  wire::Sample<neurosim_ContactModel> cm_;
  wire::Sample<neurosim_SimStatus> st_;
};

class DdsLinkTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    prefix_ = std::string("dl_") + info->name() + "_" + std::to_string(::getpid()) + "_";
    station_ = "s" + std::to_string(::getpid());
    server_ = std::make_unique<HandServer>(prefix_);
    nh::DdsLinkOptions o;
    o.station_id = station_;
    o.topic_prefix = prefix_;
    o.publisher_rt_priority = o.receiver_rt_priority = 0;
    link_ = std::make_unique<nh::DdsLink>(o);
    ASSERT_TRUE(link_->wait_for_server(10));
  }
  // Publishes poses until the server has one; that sample's fields and writer.
  bool first_pose(neurosim_ToolState& out, wire::MatchedPublication& writer) {
    nh::ToolSample s;
    s.position_m = {0.01, -0.02, 0.03};
    s.orientation = {0.5, 0.5, -0.5, 0.5};
    s.velocity_m_per_s = {0.1, 0.2, -0.3};
    s.buttons = 5;
    bool got = false;
    return eventually([&] {
      s.sequence_number = ++sequence_;
      s.source_time_ns = 7000 + static_cast<std::int64_t>(sequence_);
      link_->publish(s);
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      for (const auto& rx : server_->tools.take()) {
        if (!rx.valid() || got) continue;
        out = rx.data;
        writer = server_->writer_of(rx.info.publication_handle);
        got = true;
      }
      return got;
    });
  }
  std::string prefix_, station_;
  std::unique_ptr<HandServer> server_;
  std::unique_ptr<nh::DdsLink> link_;
  std::uint64_t sequence_ = 0;
};

TEST_F(DdsLinkTest, APublishedPoseReachesTheServerWholeInTheStationsPartition) {
  neurosim_ToolState t{};
  wire::MatchedPublication w;
  ASSERT_TRUE(first_pose(t, w));
  EXPECT_EQ(wire::get_string(t.station_id), station_);
  EXPECT_EQ(wire::get_string(t.tool_id), "probe");
  EXPECT_GE(t.sequence_number, 1u);
  EXPECT_EQ(t.source_time_ns, 7000 + static_cast<std::int64_t>(t.sequence_number));
  const double p[3] = {0.01, -0.02, 0.03}, v[3] = {0.1, 0.2, -0.3}, q[4] = {0.5, 0.5, -0.5, 0.5};
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(t.position_m[i], p[i]);
    EXPECT_EQ(t.velocity_m_per_s[i], v[i]);
  }
  for (int i = 0; i < 4; ++i) EXPECT_EQ(t.orientation[i], q[i]);
  EXPECT_EQ(t.buttons, 5u);
  ASSERT_TRUE(w.matched);
  ASSERT_EQ(w.partitions.size(), 1u);
  EXPECT_EQ(w.partitions[0], wire::station_partition(station_));
}

TEST_F(DdsLinkTest, StepGapsAreSkippedModelsARestartIsNotAndRejectionsAreCounted) {
  // One model at a time, each taken before the next (the reader keeps the newest only).
  std::uint64_t n = 0;
  auto deliver = [&](std::uint64_t step, std::uint64_t seq, bool rejected = false) {
    server_->model(station_, step, seq, rejected);
    ++n;
    return eventually([&] { return link_->counters().models_received == n; });
  };
  ASSERT_TRUE(deliver(1, 11));
  ASSERT_TRUE(deliver(2, 12));
  ASSERT_TRUE(deliver(5, 13));        // steps 3 and 4 never came: 2 skipped
  ASSERT_TRUE(deliver(1, 14));        // a restarted server counts from 1 again: no gap
  ASSERT_TRUE(deliver(2, 15, true));  // the server rejected the pose it answers
  server_->model("someone-else", 9, 99);  // another station's model is not this link's
  ASSERT_TRUE(deliver(3, 16));
  const nh::DdsLinkCounters c = link_->counters();
  EXPECT_EQ(c.models_received, 6u);
  EXPECT_EQ(c.models_skipped, 2u);
  EXPECT_EQ(c.models_rejected, 1u);
  nh::ContactModelData m;
  ASSERT_TRUE(link_->take_model(m));
  EXPECT_EQ(m.server_step, 3u);
  EXPECT_EQ(m.tool_sequence, 16u);
  EXPECT_EQ(m.reference_time_ns, 1016);  // the answered pose's source time, echoed
}

TEST_F(DdsLinkTest, ARefusalCountsOnlyForThisLinksOwnWriterAndExpires) {
  neurosim_ToolState t{};
  wire::MatchedPublication w;
  ASSERT_TRUE(first_pose(t, w));
  ASSERT_TRUE(w.matched);
  EXPECT_EQ(link_->refusal(), nh::Refusal::None);
  // Another writer under this station id refused: not this link.
  std::array<std::uint8_t, 16> other = w.guid;
  other[15] ^= 0xff;
  server_->status(station_, other, neurosim_REFUSED_IDENTITY, realtime_ns());
  // This link's writer, but another station id in the entry: not this link either.
  server_->status(station_ + "x", w.guid, neurosim_REFUSED_IDENTITY, realtime_ns());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(link_->refusal(), nh::Refusal::None);
  // Its own writer: reported, with the reason.
  server_->status(station_, w.guid, neurosim_REFUSED_MAX_STATIONS, realtime_ns());
  EXPECT_TRUE(eventually([&] { return link_->refusal() == nh::Refusal::MaxStations; }));
  server_->status(station_, w.guid, neurosim_REFUSED_PARTICIPANT_LIMIT, realtime_ns());
  EXPECT_TRUE(eventually([&] { return link_->refusal() == nh::Refusal::ParticipantLimit; }));
  EXPECT_TRUE(nh::permanent(nh::Refusal::ParticipantLimit));
  EXPECT_FALSE(nh::permanent(nh::Refusal::MaxStations));
  // A refusal 3 s old: admitted since (or gone), no longer reported.
  server_->status(station_, w.guid, neurosim_REFUSED_IDENTITY, realtime_ns() - 3'000'000'000LL);
  EXPECT_TRUE(eventually([&] { return link_->refusal() == nh::Refusal::None; }));
}

TEST(DdsLink, AStationIdIsRequired) {
  nh::DdsLinkOptions o;
  o.topic_prefix = "dl_empty_";
  EXPECT_THROW(nh::DdsLink{o}, std::invalid_argument);
}

}  // namespace
