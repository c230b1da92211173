// StationAdmission without DDS traffic: samples as the ToolState reader hands them over, writers
// as discovery describes them (service_parts_fixtures.hpp).
#include "server/service/station_admission.hpp"

#include "tests/server/service/service_parts_fixtures.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace {

using namespace neurosim::service;
using neurosim::service::testing::FakeDirectory;
using neurosim::service::testing::guid_of;
using neurosim::service::testing::SampleIn;

constexpr std::int64_t kSecond = 1000000000;

struct Admission {
  explicit Admission(StationAdmissionDef def = {}) : a(std::move(def), [this](const std::string& l) { log.push_back(l); }, [this] { ++wakes; }) {
    a.set_directory(&directory);
  }
  void send(dds_instance_handle_t writer, const std::string& station, std::uint64_t seq, std::int64_t t_ns) {
    const SampleIn s(writer, station, seq, 0.0, t_ns);
    a.handle(s.rx(), ReceiveTime{t_ns, t_ns});
  }
  std::vector<neurosim_StationRefusal> refusals() const {
    std::vector<neurosim_StationRefusal> r(StationAdmission::kMaxRefusals);
    r.resize(a.copy_refusals(r.data(), r.size()));
    return r;
  }
  int active() const {
    int n = 0;
    for (const auto& s : a.slots()) n += s.state.load() == kSlotActive ? 1 : 0;
    return n;
  }
  FakeDirectory directory;
  std::vector<std::string> log;
  int wakes{0};
  StationAdmission a;
};

TEST(service_station_admission, AStationJoinsOnItsWritersFirstSampleAndItsPoseReachesTheSlot) {
  Admission t;
  t.directory.add(7, "omni-1", 1);
  t.send(7, "omni-1", 1, 10 * kSecond);
  ASSERT_EQ(t.active(), 1);
  const StationSlot& s = t.a.slots()[0];
  EXPECT_STREQ(s.station_id, "omni-1");
  EXPECT_EQ(s.accepted.load(), 1u);
  EXPECT_EQ(t.wakes, 1) << "the step thread is woken once per pose";
  EXPECT_FALSE(t.a.status_soon());
  EXPECT_TRUE(t.refusals().empty());
}

TEST(service_station_admission, ASampleForAnotherStationThanItsWritersPartitionIsRefusedAtOnce) {
  Admission t;
  t.directory.add(7, "omni-1", 1);
  t.send(7, "omni-2", 1, 10 * kSecond);
  EXPECT_EQ(t.active(), 0);
  EXPECT_EQ(t.a.rejected_identity(), 1u);
  const auto r = t.refusals();
  ASSERT_EQ(r.size(), 1u);
  EXPECT_STREQ(r[0].station_id, "omni-2");
  EXPECT_EQ(r[0].reason, neurosim_REFUSED_IDENTITY);
  EXPECT_TRUE(t.a.status_soon()) << "a refusal asks for an early SimStatus";
}

TEST(service_station_admission, AStationIdBoundToOneWriterRefusesASecondWriter) {
  Admission t;
  t.directory.add(7, "omni-1", 1);
  t.directory.add(8, "omni-1", 2);
  t.send(7, "omni-1", 1, 10 * kSecond);
  t.send(8, "omni-1", 1, 10 * kSecond + 1000000);
  EXPECT_EQ(t.active(), 1);
  EXPECT_EQ(t.a.slots()[0].writer, 7u);
  const auto r = t.refusals();
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(std::memcmp(r[0].writer_guid, guid_of(8).data(), 16), 0);
}

// A participant with 300 idle ToolState writers, each in its own station's partition and each
// having sent one sample: with the per-participant limit they evict each other and never fill
// the 256-writer table, so a station of another participant joins afterwards.
TEST(service_station_admission, OneParticipantCannotFillTheWriterTable) {
  Admission t;
  std::int64_t now = 10 * kSecond;
  for (int w = 0; w < 300; ++w) {
    const auto h = static_cast<dds_instance_handle_t>(100 + w);
    t.directory.add(h, "squat-" + std::to_string(w), 1);
    t.send(h, "squat-" + std::to_string(w), 1, now);
    now += 1000000;
  }
  const std::size_t per = t.a.writers().limits().max_per_participant;
  EXPECT_LE(t.a.writers().count_of(guid_of(1001)), per);
  EXPECT_LE(t.a.writers().size(), per);
  EXPECT_GE(t.a.counters.writers_evicted.load(), 300u - per);
  EXPECT_EQ(t.active(), 2) << "the squatter holds its limit of stations, no more";
  // The legitimate station, right after (the squatter's writers are not idle for long).
  t.directory.add(7, "omni-1", 2);
  t.send(7, "omni-1", 1, now);
  EXPECT_EQ(t.active(), 3);
  for (const auto& r : t.refusals()) EXPECT_STRNE(r.station_id, "omni-1");
}

TEST(service_station_admission, AFullWriterTableEvictsTheWriterIdleLongest) {
  StationAdmissionDef def;
  def.writers.max_writers = 3;
  Admission t(def);
  for (int w = 0; w < 3; ++w) {
    t.directory.add(static_cast<dds_instance_handle_t>(10 + w), "s" + std::to_string(w), 10 + w);
  }
  t.send(10, "s0", 1, 10 * kSecond);  // idle longest
  t.send(11, "s1", 1, 11 * kSecond);
  t.send(12, "s2", 1, 12 * kSecond);
  // s0 and s1 stop sending, but their stations are still bound (not yet idle 2 s at 12.5 s):
  // bound writers are never evicted, so the newcomer finds no room.
  t.directory.add(13, "s3", 13);
  t.send(13, "s3", 1, 12 * kSecond + kSecond / 2);
  ASSERT_EQ(t.refusals().size(), 1u);
  EXPECT_STREQ(t.refusals()[0].station_id, "s3");
  EXPECT_EQ(t.refusals()[0].reason, neurosim_REFUSED_MAX_STATIONS);
  EXPECT_TRUE(t.a.status_soon()) << "the refused station is told at once";
  // The sweep frees the idle stations; then the writer idle longest (s0's) makes room.
  t.a.sweep(13 * kSecond + kSecond / 2, 13 * kSecond);
  t.send(13, "s3", 2, 13 * kSecond + kSecond / 2);
  EXPECT_EQ(t.a.counters.writers_evicted.load(), 1u);
  EXPECT_FALSE(t.a.writers().find(10).has_value()) << "s0's writer was idle longest";
  EXPECT_TRUE(t.a.writers().find(11).has_value());
  EXPECT_TRUE(t.a.writers().find(13).has_value());
}

TEST(service_station_admission, AParticipantHoldsAtMostItsLimitOfStations) {
  Admission t;
  for (int w = 0; w < 3; ++w) t.directory.add(static_cast<dds_instance_handle_t>(20 + w), "p" + std::to_string(w), 5);
  for (int w = 0; w < 3; ++w) t.send(static_cast<dds_instance_handle_t>(20 + w), "p" + std::to_string(w), 1, 10 * kSecond);
  EXPECT_EQ(t.active(), 2);
  ASSERT_EQ(t.refusals().size(), 1u);
  EXPECT_EQ(t.refusals()[0].reason, neurosim_REFUSED_PARTICIPANT_LIMIT);
  EXPECT_EQ(t.a.counters.stations_refused.load(), 1u);
}

TEST(service_station_admission, IdleStationsAndGoneWritersFreeTheirSlots) {
  Admission t;
  t.directory.add(7, "a", 1);
  t.directory.add(8, "b", 2);
  t.send(7, "a", 1, 10 * kSecond);
  t.send(8, "b", 1, 11 * kSecond + kSecond / 2);
  t.directory.remove(8);  // b's writer is gone
  t.a.sweep(12 * kSecond + kSecond / 10, 12 * kSecond);
  EXPECT_EQ(t.active(), 0);
  EXPECT_EQ(t.a.counters.stations_reclaimed.load(), 1u) << "a was idle; b's writer left";
  for (const auto& s : t.a.slots()) EXPECT_NE(s.state.load(), kSlotActive);
}

TEST(service_station_admission, WriterLimitsBelowTheStationsPerParticipantAreRefused) {
  StationAdmissionDef def;
  def.max_stations_per_participant = 8;
  def.writers.max_per_participant = 8;
  EXPECT_THROW(def.validate(), std::invalid_argument);
  def.writers.max_per_participant = 9;
  EXPECT_NO_THROW(def.validate());
}

}  // namespace
