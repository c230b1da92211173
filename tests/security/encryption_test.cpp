// Traffic of a secured session is encrypted: the UDP payloads on loopback to the session's DDS
// ports are captured (raw AF_PACKET socket, loopback_capture.hpp) while a station presses the box
// at a known position and the server answers. In an unsecured control run the position's bytes
// (ToolState, station -> server), the scene name (SimStatus / MeshTopology, server -> clients)
// and the ToolState type name (discovery) are on the wire; in the secured run none of them is.
#include "tests/security/loopback_capture.hpp"
#include "tests/security/secure_session.hpp"

#include <cstring>

namespace sec = neurosim::security::testing;
namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;

namespace {

// A press position whose 24 bytes (three doubles as XCDR little-endian puts them) are unlikely
// anywhere else.
std::array<double, 3> marked_position() {
  auto p = sec::press_position();
  p[1] += 1.234567e-5;
  p[2] -= 7.654321e-6;
  return p;
}

std::string bytes_of(const std::array<double, 3>& p) {
  std::string s(sizeof(double) * 3, '\0');
  std::memcpy(s.data(), p.data(), s.size());
  return s;
}

struct Seen {
  bool position = false, scene_name = false, type_name = false;
  std::size_t packets = 0, models = 0;
};

// One session on `domain`: the server child with `server_env`, this process as station `id`
// (its domain's configuration set by the caller), pressing for 2 s while the loopback is captured.
Seen run_session(const sec::ChildEnv& server_env, int domain, const std::string& id, const sec::fs::path& log) {
  Seen seen;
  sec::LoopbackCapture capture(domain);
  st::ChildProcess server(sec::kEnv, sec::with_env(server_env, sec::fake_server_exe(), sec::fake_server_args(domain, 30)),
                          log);
  {
    st::Client client(domain);
    st::StatusWatcher status(client);
    EXPECT_TRUE(status.wait_for([](const neurosim_SimStatus&) { return true; }, 30)) << server.log();
    st::ModelCollector models(client);
    sec::PartitionToolWriter w(client.pp, client.tool_topic, neurosim::wire::station_partition(id));
    EXPECT_GT(w.created(), 0) << dds_strretcode(w.created());
    if (w.created() > 0) {
      std::uint64_t seq = 0;
      sec::write_for(w, id, marked_position(), 2.0, seq);
    }
    models.wait_for([&] { return models.count(id) > 100; }, 5);
    seen.models = models.count(id);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the last packets
  seen.packets = capture.packets();
  seen.position = capture.contains(bytes_of(marked_position()));
  seen.scene_name = capture.contains(sec::kFakeSceneName);
  // The type name is in discovery (SEDP) only; the topic name is also in the permissions
  // document every participant sends in clear during authentication (docs/security.md).
  seen.type_name = capture.contains(neurosim::wire::TopicTraits<neurosim_ToolState>::descriptor()->m_typename);
  return seen;
}

}  // namespace

TEST(security_encryption, NoPlaintextSampleOnTheWire) {
  const auto dir = nt::temp_dir("security_encryption");
  // Control: unsecured (this process's first domain uses the test's loopback.xml). If the
  // capture or the markers were wrong this would fail, so the secured check below can fail too.
  const int plain_domain = st::private_domain();
  const Seen plain = run_session(sec::ChildEnv::plain(), plain_domain, "s1", dir / "plain_server.log");
  ASSERT_GT(plain.models, 100u) << "control: the unsecured server did not serve the station";
  EXPECT_TRUE(plain.position) << "control: the ToolState position bytes were not captured (" << plain.packets
                              << " packets)";
  EXPECT_TRUE(plain.scene_name) << "control: the scene name was not captured";
  EXPECT_TRUE(plain.type_name) << "control: discovery (the ToolState type name) was not captured";

  const auto pki = sec::make_pki("encryption", {"s1"});
  sec::join_as(pki, "station-s1");
  const Seen secured =
      run_session(sec::ChildEnv::secured(pki, "server"), sec::other_domain(plain_domain), "s1", dir / "server.log");
  ASSERT_GT(secured.models, 100u) << "the secured server did not serve the station";
  EXPECT_GT(secured.packets, 1000u) << "the secured session's traffic was not captured";
  EXPECT_FALSE(secured.position) << "a ToolState position is readable on the wire";
  EXPECT_FALSE(secured.scene_name) << "the scene name (SimStatus / MeshTopology) is readable on the wire";
  EXPECT_FALSE(secured.type_name) << "discovery (the ToolState type name) is readable on the wire";
}
