// Station identity: a writer's claim from its partitions, and the table of writers (bounded in
// total and per participant, the idlest evicted, bound writers never).
#include "server/service/station_identity.hpp"

#include "idl/wire/qos.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {

using neurosim::service::Admitted;
using neurosim::service::Guid;
using neurosim::service::WriterClaims;
using neurosim::service::WriterInfo;
using neurosim::service::WriterLimits;

WriterInfo writer_of(int participant, std::int64_t seen_ns) {
  WriterInfo w;
  w.claim = "s";
  w.participant = Guid{};
  w.participant[0] = static_cast<std::uint8_t>(participant);
  w.last_seen_mono_ns = seen_ns;
  return w;
}

}  // namespace

TEST(service_station_identity, AWriterClaimsTheOneStationOfItsPartition) {
  using neurosim::service::station_claim;
  EXPECT_EQ(station_claim({"neurosim.station.omni-1"}).value_or("-"), "omni-1");
  EXPECT_FALSE(station_claim({}).has_value()) << "default partition: no claim";
  EXPECT_FALSE(station_claim({"neurosim.station.*"}).has_value()) << "a wildcard claims nothing";
  EXPECT_FALSE(station_claim({"neurosim.station.a", "neurosim.station.b"}).has_value());
  EXPECT_EQ(station_claim({"other", "neurosim.station.a"}).value_or("-"), "a");
  EXPECT_FALSE(station_claim({"neurosim.station." + std::string(65, 'x')}).has_value());
  EXPECT_EQ(neurosim::wire::station_partition("omni-1"), "neurosim.station.omni-1");
  EXPECT_THROW(neurosim::wire::station_partition("a*"), std::invalid_argument);
  EXPECT_THROW(neurosim::wire::station_partition(""), std::invalid_argument);
  EXPECT_THROW(neurosim::wire::writer_qos(neurosim::wire::Profile::ToolState), std::logic_error);
}

TEST(service_station_identity, AParticipantsWritersEvictEachOtherNeverAnotherParticipants) {
  WriterLimits l;
  l.max_writers = 4;
  l.max_per_participant = 2;
  WriterClaims claims(l);
  const auto none = [](dds_instance_handle_t) { return false; };
  EXPECT_EQ(claims.admit(1, writer_of(1, 10), none), Admitted::kCached);
  EXPECT_EQ(claims.admit(2, writer_of(1, 20), none), Admitted::kCached);
  EXPECT_EQ(claims.admit(3, writer_of(2, 30), none), Admitted::kCached);
  dds_instance_handle_t evicted = 0;
  EXPECT_EQ(claims.admit(4, writer_of(1, 40), none, &evicted), Admitted::kEvictedOwn);
  EXPECT_EQ(evicted, 1u) << "participant 1's writer idle longest";
  EXPECT_TRUE(claims.find(3).has_value()) << "another participant's writer stays";
  EXPECT_EQ(claims.count_of(writer_of(1, 0).participant), 2u);
  // A bound (pinned) writer is never evicted: participant 1's next writer evicts the other one.
  const auto pin2 = [](dds_instance_handle_t h) { return h == 2; };
  EXPECT_EQ(claims.admit(5, writer_of(1, 50), pin2, &evicted), Admitted::kEvictedOwn);
  EXPECT_EQ(evicted, 4u);
}

TEST(service_station_identity, AFullTableEvictsOnlyAWriterIdleLongEnough) {
  WriterLimits l;
  l.max_writers = 2;
  l.max_per_participant = 2;
  l.evict_idle_ns = 1000;
  WriterClaims claims(l);
  const auto none = [](dds_instance_handle_t) { return false; };
  claims.admit(1, writer_of(1, 0), none);
  claims.admit(2, writer_of(2, 500), none);
  EXPECT_EQ(claims.admit(3, writer_of(3, 900), none), Admitted::kFull) << "nobody idle 1000 ns yet";
  claims.touch(1, 800);
  dds_instance_handle_t evicted = 0;
  EXPECT_EQ(claims.admit(3, writer_of(3, 1600), none, &evicted), Admitted::kEvictedIdle);
  EXPECT_EQ(evicted, 2u) << "writer 2 (seen at 500) was idle longer than writer 1 (touched at 800)";
  EXPECT_THROW(WriterClaims(WriterLimits{0, 1, 0}), std::invalid_argument);
}
