// The QoS profiles (idl/wire/qos.hpp) against the published contract: every topic's row of the
// table in docs/ARCHITECTURE.md "DDS" (reliability, durability, history, liveliness,
// autodispose, partitions) is read from the document and compared field by field with the
// dds_qos_t that writer_qos / reader_qos / tool_state_writer_qos build. Station ids that would
// break the partition contract are refused. No DDS entity is created (QoS objects only).
#include "idl/wire/qos.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <map>
#include <sstream>
#include <string>

namespace ns = neurosim::wire;

namespace {

using ns::Profile;

const Profile kProfiles[] = {Profile::ToolState, Profile::ContactModel, Profile::Deformation,
                             Profile::MeshTopology, Profile::SimStatus};

const char* topic_name(Profile p) {
  switch (p) {
    case Profile::ToolState:
      return "ToolState";
    case Profile::ContactModel:
      return "ContactModel";
    case Profile::Deformation:
      return "Deformation";
    case Profile::MeshTopology:
      return "MeshTopology";
    case Profile::SimStatus:
      return "SimStatus";
  }
  return "?";
}

// The QoS column of each topic's row in docs/ARCHITECTURE.md ("| `Topic` | ... | qos |").
std::map<std::string, std::string> documented_qos() {
  std::istringstream in(
      neurosim::testing::slurp(neurosim::testing::source_dir() / "docs/ARCHITECTURE.md"));
  std::map<std::string, std::string> out;
  std::string line;
  while (std::getline(in, line)) {
    for (Profile p : kProfiles) {
      const std::string head = std::string("| `") + topic_name(p) + "` |";
      if (line.rfind(head, 0) != 0) continue;
      const auto end = line.find_last_of('|');
      const auto start = line.find_last_of('|', end - 1);
      out[topic_name(p)] = line.substr(start + 1, end - start - 1);
    }
  }
  return out;
}

bool says(const std::string& text, const std::string& words) {
  return text.find(words) != std::string::npos;
}

struct Fields {
  dds_reliability_kind_t reliability{};
  dds_duration_t max_blocking{};
  dds_durability_kind_t durability{};
  dds_history_kind_t history{};
  int32_t depth{};
  bool has_liveliness{false};
  dds_liveliness_kind_t liveliness{};
  dds_duration_t lease{};
  bool has_lifecycle{false};
  bool autodispose{true};  // the DDS default when not set
};

Fields fields(const ns::Qos& q) {
  Fields f;
  EXPECT_TRUE(dds_qget_reliability(q.get(), &f.reliability, &f.max_blocking));
  EXPECT_TRUE(dds_qget_durability(q.get(), &f.durability));
  EXPECT_TRUE(dds_qget_history(q.get(), &f.history, &f.depth));
  f.has_liveliness = dds_qget_liveliness(q.get(), &f.liveliness, &f.lease);
  f.has_lifecycle = dds_qget_writer_data_lifecycle(q.get(), &f.autodispose);
  return f;
}

void expect_shared_fields(const std::string& doc, const Fields& f, const std::string& what) {
  ASSERT_TRUE(says(doc, "best effort") != says(doc, "reliable")) << what << ": " << doc;
  EXPECT_EQ(f.reliability,
            says(doc, "best effort") ? DDS_RELIABILITY_BEST_EFFORT : DDS_RELIABILITY_RELIABLE)
      << what;
  if (f.reliability == DDS_RELIABILITY_RELIABLE) {
    EXPECT_GT(f.max_blocking, 0) << what;
  }
  ASSERT_TRUE(says(doc, "volatile") != says(doc, "transient-local")) << what << ": " << doc;
  EXPECT_EQ(f.durability,
            says(doc, "volatile") ? DDS_DURABILITY_VOLATILE : DDS_DURABILITY_TRANSIENT_LOCAL)
      << what;
  ASSERT_TRUE(says(doc, "keep-last 1")) << what << ": " << doc;
  EXPECT_EQ(f.history, DDS_HISTORY_KEEP_LAST) << what;
  EXPECT_EQ(f.depth, 1) << what;
}

TEST(wire_qos, EveryProfileIsTheDocumentedOne) {
  const auto doc = documented_qos();
  ASSERT_EQ(doc.size(), std::size(kProfiles)) << "a topic row missing in docs/ARCHITECTURE.md";
  for (Profile p : kProfiles) {
    const std::string& d = doc.at(topic_name(p));
    SCOPED_TRACE(std::string(topic_name(p)) + ":" + d);
    const Fields topic = fields(ns::topic_qos(p));
    expect_shared_fields(d, topic, "topic");
    const Fields writer =
        fields(p == Profile::ToolState ? ns::tool_state_writer_qos("omni-1") : ns::writer_qos(p));
    const Fields reader = fields(ns::reader_qos(p));
    expect_shared_fields(d, writer, "writer");
    expect_shared_fields(d, reader, "reader");
    // Liveliness: offered by the writer as documented; readers request the default lease.
    const bool live = says(d, "liveliness automatic 500 ms");
    EXPECT_EQ(writer.has_liveliness, live);
    if (live) {
      EXPECT_EQ(writer.liveliness, DDS_LIVELINESS_AUTOMATIC);
      EXPECT_EQ(writer.lease, DDS_MSECS(500));
      EXPECT_EQ(writer.lease, ns::kLivelinessLease);
    }
    EXPECT_FALSE(reader.has_liveliness);
    EXPECT_FALSE(topic.has_liveliness);
    // Autodispose: on unless documented otherwise.
    EXPECT_EQ(writer.autodispose, !says(d, "no autodispose"));
    // Partitions: only ToolState's, as documented.
    const auto wp = ns::partitions_of(
        (p == Profile::ToolState ? ns::tool_state_writer_qos("omni-1") : ns::writer_qos(p)).get());
    const auto rp = ns::partitions_of(ns::reader_qos(p).get());
    if (p == Profile::ToolState) {
      ASSERT_TRUE(says(d, "`neurosim.station.<station_id>`") && says(d, "`neurosim.station.*`"));
      EXPECT_EQ(wp, std::vector<std::string>{"neurosim.station.omni-1"});
      EXPECT_EQ(rp, std::vector<std::string>{"neurosim.station.*"});
    } else {
      EXPECT_FALSE(says(d, "partition"));
      EXPECT_TRUE(wp.empty());
      EXPECT_TRUE(rp.empty());
    }
    EXPECT_TRUE(ns::partitions_of(ns::topic_qos(p).get()).empty());
  }
}

TEST(wire_qos, ToolStateWriterNeedsItsStation) {
  const std::string m = neurosim::testing::message_of([] { ns::writer_qos(Profile::ToolState); });
  EXPECT_NE(m.find("tool_state_writer_qos"), std::string::npos) << m;
  EXPECT_THROW(ns::writer_qos(Profile::ToolState), std::logic_error);
}

TEST(wire_qos, StationIdsThatBreakThePartitionAreRefused) {
  EXPECT_EQ(ns::station_partition("omni-1"), "neurosim.station.omni-1");
  const std::string longest(neurosim_ID_MAX, 'a');
  EXPECT_EQ(ns::station_partition(longest), ns::kStationPartitionPrefix + longest);
  const std::string too_long(neurosim_ID_MAX + 1, 'a');
  EXPECT_NE(neurosim::testing::message_of([&] {
              ns::station_partition(too_long);
            }).find("longer than " + std::to_string(neurosim_ID_MAX)),
            std::string::npos);
  EXPECT_NE(neurosim::testing::message_of([] { ns::station_partition(""); }).find("empty"),
            std::string::npos);
  for (const char* id : {"omni*", "a?b", "st[1]", "x]", "back\\slash"}) {
    const std::string m = neurosim::testing::message_of([&] { ns::station_partition(id); });
    EXPECT_NE(m.find(std::string("'") + id + "'"), std::string::npos) << id << ": " << m;
    EXPECT_NE(m.find("wildcard"), std::string::npos) << id << ": " << m;
    EXPECT_THROW(ns::tool_state_writer_qos(id), std::invalid_argument) << id;
  }
}

TEST(wire_qos, CopiesAreIndependentAndMovesTransfer) {
  ns::Qos a = ns::reader_qos(Profile::ToolState);
  ns::Qos b = a;  // copy
  ASSERT_NE(a.get(), b.get());
  dds_qset_history(b.get(), DDS_HISTORY_KEEP_LAST, 7);
  dds_history_kind_t kind{};
  int32_t depth = 0;
  ASSERT_TRUE(dds_qget_history(a.get(), &kind, &depth));
  EXPECT_EQ(depth, 1) << "changing the copy changed the original";
  EXPECT_EQ(ns::partitions_of(b.get()), std::vector<std::string>{"neurosim.station.*"});
  dds_qos_t* raw = b.get();
  ns::Qos c = std::move(b);
  EXPECT_EQ(c.get(), raw);
  a = c;  // copy assignment
  ASSERT_TRUE(dds_qget_history(a.get(), &kind, &depth));
  EXPECT_EQ(depth, 7);
  EXPECT_TRUE(ns::partitions_of(nullptr).empty());
}

TEST(wire_qos, ProfileNamesAreDistinct) {
  std::map<std::string, int> seen;
  for (Profile p : kProfiles) ++seen[ns::to_string(p)];
  EXPECT_EQ(seen.size(), std::size(kProfiles));
  EXPECT_EQ(std::string(ns::to_string(Profile::SimStatus)), "sim_status");
}

}  // namespace
