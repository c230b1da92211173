// Who may join a secured session (deploy/cyclonedds/secure.xml, deploy/secure/make-test-pki):
// the server code (service_test_fake_server: server/service with the test-only analytic physics)
// runs as identity "server" on a private domain on loopback; this process joins as one identity.
//   - a participant without a certificate (loopback.xml) cannot inject a ToolState the server acts
//     on (control: against an unsecured server the same child is served);
//   - a certified viewer may read the server's topics and the stations' ToolState but cannot
//     create a ToolState writer in any partition;
//   - a station cannot write under another station's id: a writer in another station's partition
//     is refused by access control, and another id in its own partition is rejected by the server
//     (cause "identity");
//   - a legitimate secured station gets ContactModels end to end.
#include "tests/security/secure_session.hpp"

namespace sec = neurosim::security::testing;
namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace wire = neurosim::wire;

namespace {

constexpr double kServerSeconds = 40;  // each server's bound; the tests end it earlier
namespace fs = std::filesystem;

// A running server child and this process's client on its domain (identity set beforehand).
struct Served {
  Served(const sec::ChildEnv& env, int domain_id, const fs::path& dir)
      : domain(domain_id),
        log(dir / ("server_" + std::to_string(domain_id) + ".log")),
        server(sec::kEnv, sec::with_env(env, sec::fake_server_exe(), sec::fake_server_args(domain_id, kServerSeconds)),
               log),
        client(domain_id),
        status(client) {}
  ::testing::AssertionResult wait_ready() {
    if (status.wait_for([](const neurosim_SimStatus&) { return true; }, 30)) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "no SimStatus from the server within 30 s; server log:\n" << server.log();
  }
  int domain;
  fs::path log;
  st::ChildProcess server;
  st::Client client;
  st::StatusWatcher status;
};

// The scripted station child (tests/server/service/station_child.cpp) pressing the box as `id`.
std::vector<std::string> station_args(int domain, const std::string& id) {
  const auto p = sec::press_position();
  return {std::to_string(domain), id, std::to_string(p[0]), std::to_string(p[1]), std::to_string(p[2])};
}
fs::path station_exe() { return nt::bin_dir() / "service_test_station"; }

}  // namespace

TEST(security_access, UncertifiedParticipantCannotInjectToolState) {
  const auto dir = nt::temp_dir("security_uncertified");
  // Control, all unsecured: the server serves the intruder child, so its absence below means
  // something. This process's first domain is made with the test's plain loopback.xml.
  {
    Served plain(sec::ChildEnv::plain(), st::private_domain(), dir);
    ASSERT_TRUE(plain.wait_ready());
    st::ModelCollector models(plain.client);
    st::ChildProcess intruder(sec::kEnv, sec::with_env(sec::ChildEnv::plain(), station_exe(),
                                                       station_args(plain.domain, "intruder")),
                              dir / "intruder_control.log");
    EXPECT_TRUE(models.wait_for([&] { return models.count("intruder") > 20; }, 10))
        << "control: the unsecured server did not answer the scripted station\n" << intruder.log() << plain.server.log();
    EXPECT_TRUE(plain.status.wait_for([](const neurosim_SimStatus& s) { return st::find_station(s, "intruder"); }, 5))
        << plain.status.last_text;
  }
  // Secured: the same child with the plain configuration on the secured server's domain.
  const auto pki = sec::make_pki("uncertified", {"s1"});
  sec::join_as(pki, "station-s1");
  Served secured(sec::ChildEnv::secured(pki, "server"), st::private_domain(), dir);
  ASSERT_TRUE(secured.wait_ready());
  st::ModelCollector models(secured.client);
  st::ChildProcess intruder(sec::kEnv, sec::with_env(sec::ChildEnv::plain(), station_exe(),
                                                     station_args(secured.domain, "intruder")),
                            dir / "intruder.log");
  // 5 s of 1 kHz samples (the control was served within 1 s); the server keeps publishing.
  const std::uint64_t steps0 = secured.status.last_steps;
  EXPECT_FALSE(secured.status.wait_for([](const neurosim_SimStatus& s) { return st::find_station(s, "intruder"); }, 5))
      << secured.status.last_text;
  EXPECT_GT(secured.status.last_steps, steps0) << "the secured server's SimStatus stopped: " << secured.server.log();
  EXPECT_TRUE(intruder.alive()) << "the intruder child must have been writing all along: " << intruder.log();
  EXPECT_EQ(models.count("intruder"), 0u);
}

TEST(security_access, CertifiedViewerCannotPublishToolState) {
  const auto dir = nt::temp_dir("security_viewer");
  const auto pki = sec::make_pki("viewer", {"s1"});
  sec::join_as(pki, "viewer");
  const int domain = st::private_domain();
  st::ChildProcess server(sec::kEnv,
                          sec::with_env(sec::ChildEnv::secured(pki, "server"), sec::fake_server_exe(),
                                        sec::fake_server_args(domain, kServerSeconds)),
                          dir / "server.log");
  // The viewer joins and reads the server's status (it is a legitimate participant) ...
  wire::Participant pp(st::Client::options(domain));
  wire::Topic<neurosim_SimStatus> status_topic(pp);
  wire::Reader<neurosim_SimStatus> status(pp, status_topic);
  ASSERT_TRUE(status.wait_for_writers(1, DDS_SECS(30))) << server.log();
  // ... and may read every station's ToolState (it draws the tools: subscribe in the station
  // partitions), but publish it in no partition.
  const wire::Qos q = wire::topic_qos(wire::Profile::ToolState);
  const dds_entity_t topic = dds_create_topic(pp.handle(), wire::TopicTraits<neurosim_ToolState>::descriptor(),
                                              wire::topic_name<neurosim_ToolState>().c_str(), q.get(), nullptr);
  ASSERT_GT(topic, 0) << "viewer may subscribe to ToolState: " << dds_strretcode(topic);
  {
    dds_qos_t* sq = dds_create_qos();
    const char* parts[] = {wire::kToolStateReaderPartition};
    dds_qset_partition(sq, 1, parts);
    const dds_entity_t sub = dds_create_subscriber(pp.handle(), sq, nullptr);
    dds_delete_qos(sq);
    EXPECT_GT(dds_create_reader(sub, topic, q.get(), nullptr), 0) << "ToolState reader refused";
  }
  for (const std::string part : {"neurosim.station.viewer", "neurosim.station.s1", ""}) {
    dds_qos_t* pq = dds_create_qos();
    const char* parts[] = {part.c_str()};
    dds_qset_partition(pq, 1, parts);
    const dds_entity_t pub = dds_create_publisher(pp.handle(), pq, nullptr);
    dds_delete_qos(pq);
    EXPECT_EQ(dds_create_writer(pub, topic, q.get(), nullptr), DDS_RETCODE_NOT_ALLOWED_BY_SECURITY)
        << "partition '" << part << "'";
  }
}

TEST(security_access, StationCannotWriteUnderAnotherStationsId) {
  const auto dir = nt::temp_dir("security_impersonate");
  const auto pki = sec::make_pki("impersonate", {"s1", "s2"});
  sec::join_as(pki, "station-s1");
  Served ses(sec::ChildEnv::secured(pki, "server"), st::private_domain(), dir);
  ASSERT_TRUE(ses.wait_ready());
  st::ModelCollector models(ses.client);
  // Access control: station s1's certificate may publish ToolState only in its own partition.
  for (const std::string part : {"neurosim.station.s2", "neurosim.station.*", ""}) {
    sec::PartitionToolWriter w(ses.client.pp, ses.client.tool_topic, part);
    EXPECT_EQ(w.created(), DDS_RETCODE_NOT_ALLOWED_BY_SECURITY) << "station s1 writing in partition '" << part << "'";
  }
  // Its own partition: s1 is served (the writer is bound to s1) ...
  sec::PartitionToolWriter own(ses.client.pp, ses.client.tool_topic, "neurosim.station.s1");
  ASSERT_GT(own.created(), 0) << dds_strretcode(own.created());
  std::uint64_t seq = 0;
  const auto t0 = st::Clock::now();
  while (models.count("s1") < 20 && st::seconds_since(t0) < 15) sec::write_for(own, "s1", sec::press_position(), 0.1, seq);
  ASSERT_GE(models.count("s1"), 20u) << "the secured server did not serve station s1\n" << ses.server.log();
  // ... and samples claiming s2 from the same writer are rejected (cause identity).
  std::uint64_t seq2 = 0;
  sec::write_for(own, "s2", sec::press_position(0.02), 2.0, seq2);
  EXPECT_TRUE(ses.status.wait_for([](const neurosim_SimStatus& s) { return s.samples_rejected_identity > 0; }, 5))
      << ses.status.last_text << "\n" << ses.server.log();
  EXPECT_FALSE(ses.status.wait_for(
      [](const neurosim_SimStatus& s) {
        const auto* s2 = st::find_station(s, "s2");
        return s2 != nullptr && s2->samples_accepted > 0;
      },
      1.0))
      << ses.status.last_text;
  EXPECT_EQ(models.count("s2"), 0u);
}

TEST(security_access, CertifiedStationGetsContactModels) {
  const auto dir = nt::temp_dir("security_session");
  const auto pki = sec::make_pki("session", {"s1"});
  sec::join_as(pki, "station-s1");
  Served ses(sec::ChildEnv::secured(pki, "server"), st::private_domain(), dir);
  ASSERT_TRUE(ses.wait_ready());
  st::ModelCollector models(ses.client);
  sec::PartitionToolWriter w(ses.client.pp, ses.client.tool_topic, wire::station_partition("s1"));
  ASSERT_GT(w.created(), 0) << dds_strretcode(w.created());
  std::uint64_t seq = 0;
  sec::write_for(w, "s1", sec::press_position(), 2.0, seq);
  ASSERT_TRUE(models.wait_for([&] { return models.count("s1") > 200; }, 5))
      << models.count("s1") << " ContactModels\n" << ses.server.log();
  bool contact = false;
  for (const auto& r : models.records())
    if (r.station == "s1" && r.in_contact) contact = r.f0[0] > 0;  // pushed back out of the +x face
  EXPECT_TRUE(contact) << "no ContactModel in contact pushing out of the box";
  EXPECT_TRUE(ses.status.wait_for(
      [](const neurosim_SimStatus& s) {
        const auto* s1 = st::find_station(s, "s1");
        return s1 != nullptr && s1->samples_accepted > 200;
      },
      5))
      << ses.status.last_text;
}
