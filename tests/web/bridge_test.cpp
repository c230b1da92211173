// neurosim-web (the real program, a child process on a free loopback port) against a fake server
// in this process that publishes MeshTopology, Deformation, ContactModel and SimStatus:
//  - every request needs the token (401 without it or with a wrong one; URL or Bearer header);
//  - a client joining late gets the topology, then a keyframe before any delta, and can decode;
//  - a client that never reads does not slow the others (latest wins, its frames are dropped);
//  - the (N+1)-th client is refused with a message saying why;
//  - 20 clients joining and leaving five times leave the bridge's memory where it was;
//  - the bridge writes no DDS topic (the built-in publication topic shows none of it);
//  - the server going away and coming back reaches the clients.
// Every process is bounded (--duration), every wait has a timeout.
#include "web_test_util.hpp"

#include <gtest/gtest.h>

#include <iostream>
#include <sstream>

namespace wt = neurosim::web::testing;
namespace web = neurosim::web;
namespace nt = neurosim::testing;
using neurosim::common::Json;

namespace {

struct Fixture {
  std::string prefix;
  std::filesystem::path dir;
  explicit Fixture(const std::string& tag)
      : prefix(wt::unique_prefix(tag)), dir(nt::temp_dir("web_" + tag)) {}
};

// The frames a client decodes, checked as the page decodes them: a delta must find its FULL
// frame (same base frame number) already received.
struct DecodeCheck {
  std::size_t full = 0, delta = 0, undecodable = 0;
  std::size_t topology_at = std::string::npos, first_frame_at = std::string::npos;
};
DecodeCheck check_decoding(const std::vector<wt::WsClient::Received>& msgs) {
  DecodeCheck c;
  std::uint64_t base = ~0ULL;
  for (std::size_t i = 0; i < msgs.size(); ++i) {
    const auto& m = msgs[i];
    if (!m.binary) {
      if (Json::parse(m.bytes)["type"] == "topology" && c.topology_at == std::string::npos)
        c.topology_at = i;
      continue;
    }
    if (static_cast<std::uint8_t>(m.bytes[0]) != web::kKindDeformationFrame) continue;
    if (c.first_frame_at == std::string::npos) c.first_frame_at = i;
    const web::FrameHeader h = web::parse_frame_header(m.bytes.data(), m.bytes.size());
    if (h.encoding == web::kEncodingFull) {
      base = h.frame;
      ++c.full;
    } else if (h.base_frame == base) {
      ++c.delta;
    } else {
      ++c.undecodable;
    }
  }
  return c;
}

}  // namespace

TEST(WebBridge, EveryRequestNeedsTheToken) {
  Fixture f("auth");
  wt::BridgeProcess bridge(f.prefix, {}, f.dir / "web.log", 60);
  const int port = bridge.port();
  // No token, a wrong one, one of the right length but different: 401 with a clear message.
  for (const std::string target : {"/", "/app.js", "/api/stats", "/?token=wrong-token-0123456789",
                                   "/?token=test-token-0123456789abcdeX"}) {
    const wt::HttpResponse r = wt::http_request(port, "GET", target);
    EXPECT_EQ(r.status, 401) << target;
    EXPECT_NE(r.head.find("WWW-Authenticate: Bearer"), std::string::npos) << target;
    EXPECT_NE(r.body.find("an access token is required"), std::string::npos) << target;
  }
  EXPECT_EQ(
      wt::http_request(port, "GET", "/", "Authorization: Bearer wrong-token-0123456789\r\n").status,
      401);
  EXPECT_EQ(wt::http_request(port, "GET", "/ws", wt::upgrade_headers()).status, 401);
  EXPECT_EQ(wt::http_request(port, "GET", "/ws?token=nope", wt::upgrade_headers()).status, 401);
  wt::WsClient no_token(port, "wrong-token-0123456789");
  EXPECT_FALSE(no_token.connected());

  // The right token, in the URL or as a Bearer header.
  const std::string q = std::string("?token=") + wt::kToken;
  const wt::HttpResponse page = wt::http_request(port, "GET", "/" + q);
  EXPECT_EQ(page.status, 200);
  EXPECT_NE(page.body.find("app.js" + q), std::string::npos);
  EXPECT_NE(page.head.find("Referrer-Policy: no-referrer"), std::string::npos);
  const wt::HttpResponse app = wt::http_request(
      port, "GET", "/app.js", std::string("Authorization: Bearer ") + wt::kToken + "\r\n");
  EXPECT_EQ(app.status, 200);
  EXPECT_NE(app.head.find("Content-Type: text/javascript"), std::string::npos);
  EXPECT_GT(app.body.size(), 100000U);
  EXPECT_EQ(wt::http_request(port, "GET", "/api/stats" + q).status, 200);
  EXPECT_EQ(wt::http_request(port, "GET", "/nothing-here" + q).status, 404);
  EXPECT_EQ(wt::http_request(port, "POST", "/" + q).status, 405);
  wt::WsClient ok(port);
  EXPECT_TRUE(ok.connected()) << ok.error();
}

TEST(WebBridge, LateJoinerGetsTopologyThenAKeyframeAndDecodes) {
  Fixture f("late");
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  wt::FakeServer server(o);
  wt::BridgeProcess bridge(f.prefix, {}, f.dir / "web.log", 60);
  wt::WsClient early(bridge.port());
  ASSERT_TRUE(early.connected()) << early.error();
  ASSERT_TRUE(early.wait_until([&] { return early.frames() >= 40; }, 20)) << bridge.child().log();
  // Joins between two FULL frames (one per 30): its first frame must still be decodable.
  wt::WsClient late(bridge.port());
  ASSERT_TRUE(late.connected()) << late.error();
  ASSERT_TRUE(late.wait_until([&] { return late.frames() >= 10; }, 20));
  for (wt::WsClient* c : {&early, &late}) {
    const DecodeCheck d = check_decoding(c->messages());
    EXPECT_LT(d.topology_at, d.first_frame_at);
    EXPECT_GE(d.full, 1U);
    EXPECT_GE(d.delta, 5U);
    EXPECT_EQ(d.undecodable, 0U);
  }
  const Json topo = late.last_text("topology");
  EXPECT_EQ(topo["scene"], "test_scene");
  EXPECT_EQ(topo["meshes"][0]["id"], "brain");
  EXPECT_EQ(topo["meshes"][0]["vertices"], server.vertices());
  ASSERT_TRUE(late.wait_until([&] { return !late.last_text("stations").is_null(); }, 5));
  const Json st = late.last_text("stations");
  EXPECT_EQ(st["stations"][0]["id"], "fake-station");
  EXPECT_GT(st["stations"][0]["force_magnitude_n"].get<double>(), 0.05);
  ASSERT_TRUE(late.wait_until([&] { return !late.last_text("status").is_null(); }, 5));
  const Json status = late.last_text("status");
  EXPECT_EQ(status["server_alive"], true);
  EXPECT_EQ(status["server"]["scene"], "test_scene");
  EXPECT_EQ(status["server"]["tier"], "LINEAR");
}

TEST(WebBridge, AClientThatNeverReadsDoesNotStallTheOthers) {
  Fixture f("stall");
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  o.vertices = 5356;  // the brain: 64 KB FULL frames fill a stalled socket within a second
  o.frame_hz = 30;
  wt::FakeServer server(o);
  // Short timeouts so the stalled client is dropped within seconds (defaults: 5 s and 2 s).
  wt::BridgeProcess bridge(f.prefix, {"--write-timeout", "1", "--ping-period", "0.5"},
                           f.dir / "web.log", 60);
  wt::WsClient reader(bridge.port());
  ASSERT_TRUE(reader.connected()) << reader.error();
  reader.keep_messages(false);
  ASSERT_TRUE(reader.wait_until([&] { return reader.frames() >= 5; }, 20)) << bridge.child().log();
  // The share of the server's frames the reader gets over a fixed count of frames written (45,
  // 1.5 s at 30 Hz; at most 20 s on a slow machine): first alone, then beside the stalled client,
  // on the same machine under the same load. Only the stalled client differs between the two,
  // so a loaded machine lowers both; a broadcast that waits on the stalled socket (up to the
  // 1 s write timeout per frame) leaves the reader a few frames of the 45.
  const auto share_of_frames = [&] {
    const std::size_t r0 = reader.frames();
    const std::uint64_t w0 = server.frames_written();
    const auto t0 = wt::Clock::now();
    while (server.frames_written() < w0 + 45 && wt::seconds_since(t0) < 20)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const double sent = static_cast<double>(server.frames_written() - w0);
    return std::pair<double, double>{static_cast<double>(reader.frames() - r0), sent};
  };
  const auto [got_alone, sent_alone] = share_of_frames();
  wt::StalledClient stalled(bridge.port());
  std::this_thread::sleep_for(std::chrono::milliseconds(700));  // its buffers fill
  const auto [got, sent] = share_of_frames();
  ASSERT_GE(sent_alone, 45);
  ASSERT_GE(sent, 45);
  const double share_alone = got_alone / sent_alone, share = got / sent;
  std::cout << "reader got " << got_alone << " of " << sent_alone << " frames alone, " << got
            << " of " << sent << " beside the stalled client\n";
  EXPECT_GE(share_alone, 0.3) << "reader got " << got_alone << " of " << sent_alone << " alone";
  EXPECT_GE(share, 0.7 * share_alone)
      << "reader got " << got << " of " << sent << " frames beside the stalled client, "
      << got_alone << " of " << sent_alone << " alone";
  // The stalled client (it joined second: the larger id) has frames dropped while its socket is
  // full; its sends then fail and its pings go unanswered, so it is dropped, while the reader
  // (which answers pings, as a browser does) stays and keeps getting frames.
  Json last_stalled, s;
  const auto t0 = wt::Clock::now();
  for (;;) {
    s = wt::bridge_stats(bridge.port());
    if (s["clients"] != 2 || wt::seconds_since(t0) > 30) break;
    const Json& a = s["per_client"][0];
    const Json& b = s["per_client"][1];
    last_stalled = a["id"].get<int>() > b["id"].get<int>() ? a : b;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  std::cout << "the stalled client last seen: " << last_stalled.dump() << "\n";
  EXPECT_EQ(s["clients"], 1) << s.dump(2);
  ASSERT_FALSE(last_stalled.is_null());
  EXPECT_GT(last_stalled["frames_dropped"].get<std::uint64_t>(), 10U) << last_stalled.dump();
  // What reached its socket is bounded by the socket buffers, not by the run time.
  EXPECT_LT(last_stalled["bytes_sent"].get<std::uint64_t>(), 8U << 20) << last_stalled.dump();
  const std::size_t r1 = reader.frames();
  EXPECT_TRUE(reader.wait_until([&] { return reader.frames() >= r1 + 10; }, 20));
  EXPECT_NE(bridge.child().log().find("dropped, send failed"), std::string::npos)
      << bridge.child().log();
}

TEST(WebBridge, TheClientBeyondMaxClientsIsRefusedWithAReason) {
  Fixture f("max");
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  wt::FakeServer server(o);
  wt::BridgeProcess bridge(f.prefix, {"--max-clients", "2"}, f.dir / "web.log", 60);
  wt::WsClient a(bridge.port()), b(bridge.port());
  ASSERT_TRUE(a.connected() && b.connected());
  ASSERT_TRUE(a.wait_until([&] { return a.frames() > 0 && b.frames() > 0; }, 20));
  wt::WsClient c(bridge.port());
  ASSERT_TRUE(c.connected()) << c.error();  // the handshake succeeds, then the refusal comes
  ASSERT_TRUE(c.wait_until([&] { return !c.last_text("refused").is_null(); }, 10));
  EXPECT_EQ(c.last_text("refused")["reason"],
            "neurosim-web serves at most 2 clients; try again later");
  ASSERT_TRUE(c.wait_until([&] { return c.close_frame().first != 0; }, 10));
  EXPECT_EQ(c.close_frame().first, 1013);
  EXPECT_NE(c.close_frame().second.find("at most 2 clients"), std::string::npos);
  EXPECT_EQ(c.frames(), 0U);
  const Json s = wt::bridge_stats(bridge.port());
  EXPECT_EQ(s["refused"], 1);
  EXPECT_EQ(s["clients"], 2);
  EXPECT_NE(bridge.child().log().find("refused: neurosim-web serves at most 2 clients"),
            std::string::npos);
}

TEST(WebBridge, MemoryStaysFlatWithTwentyClientsJoiningAndLeaving) {
  Fixture f("mem");
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  o.vertices = 5356;  // the brain
  wt::FakeServer server(o);
  wt::BridgeProcess bridge(f.prefix, {"--max-clients", "20"}, f.dir / "web.log", 120);
  std::vector<long> rss;
  for (int round = 0; round < 5; ++round) {
    {
      std::vector<std::unique_ptr<wt::WsClient>> clients;
      for (int i = 0; i < 20; ++i) {
        clients.push_back(std::make_unique<wt::WsClient>(bridge.port()));
        ASSERT_TRUE(clients.back()->connected()) << clients.back()->error();
        clients.back()->keep_messages(false);
      }
      for (auto& c : clients)
        ASSERT_TRUE(c->wait_until([&] { return c->frames() >= 3; }, 20)) << "round " << round;
      EXPECT_EQ(wt::bridge_stats(bridge.port())["clients"], 20);
      // All leave at once (CivetWeb's client joins its thread on close: in parallel).
      std::vector<std::thread> closers;
      for (auto& c : clients) closers.emplace_back([p = c.release()] { delete p; });
      for (auto& t : closers) t.join();
    }
    Json s;
    const auto t0 = wt::Clock::now();
    do {  // the bridge sees the closes
      s = wt::bridge_stats(bridge.port());
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    } while (s["clients"] != 0 && wt::seconds_since(t0) < 15);
    ASSERT_EQ(s["clients"], 0) << s.dump(2);
    rss.push_back(s["resident_kib"].get<long>());
  }
  std::ostringstream text;
  for (long r : rss) text << r << " ";
  std::cout << "bridge resident set after each round of 20 clients, KiB: " << text.str() << "\n";
  // After the first round (buffers and thread stacks warmed up) the resident set stays flat.
  EXPECT_LT(rss.back() - rss[1], 2048) << "resident KiB after each round: " << text.str();
  EXPECT_LT(rss.back(), 64 * 1024) << text.str();
  EXPECT_EQ(wt::bridge_stats(bridge.port())["joined"], 100);
}

TEST(WebBridge, WritesNoDdsTopic) {
  Fixture f("ro");
  const int domain = 20 + static_cast<int>(getpid() % 200);
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  o.domain = domain;
  wt::FakeServer server(o);
  // Every publication (writer) of the domain, from the built-in topic.
  wt::wire::Participant watcher(wt::FakeServer::participant_options(domain));
  const dds_entity_t pubs =
      dds_create_reader(watcher.handle(), DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr);
  ASSERT_GT(pubs, 0);
  dds_guid_t server_guid{};
  ASSERT_EQ(dds_get_guid(server.participant(), &server_guid), DDS_RETCODE_OK);
  wt::BridgeProcess bridge(f.prefix, {"--domain", std::to_string(domain)}, f.dir / "web.log", 60);
  wt::WsClient c(bridge.port());
  ASSERT_TRUE(c.wait_until([&] { return c.frames() >= 5; }, 20)) << bridge.child().log();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // discovery of anything it has
  std::size_t of_server = 0, of_others = 0;
  std::vector<std::string> others;
  void* samples[64] = {};
  dds_sample_info_t infos[64];
  for (;;) {
    const dds_return_t n = dds_take(pubs, samples, infos, 64, 64);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* p = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
      // Only this test's topics (another test may share the domain number).
      if (std::string(p->topic_name).rfind(f.prefix, 0) != 0) continue;
      const bool from_server = std::memcmp(p->participant_key.v, server_guid.v, 16) == 0;
      (from_server ? of_server : of_others) += 1;
      if (!from_server) others.push_back(p->topic_name);
    }
    dds_return_loan(pubs, samples, n);
  }
  EXPECT_EQ(of_server, 4U);  // the check sees writers: the fake server's four
  std::string names;
  for (const auto& n : others) names += n + " ";
  EXPECT_EQ(of_others, 0U) << "writers not from the fake server: " << names;
}

TEST(WebBridge, ServerAwayAndBackReachesTheClients) {
  Fixture f("away");
  wt::FakeServerOptions o;
  o.topic_prefix = f.prefix;
  auto server = std::make_unique<wt::FakeServer>(o);
  wt::BridgeProcess bridge(f.prefix, {}, f.dir / "web.log", 60);
  wt::WsClient c(bridge.port());
  ASSERT_TRUE(c.wait_until([&] { return c.frames() >= 5; }, 20)) << bridge.child().log();
  const auto alive = [&](bool want) {
    const Json s = c.last_text("status");
    return !s.is_null() && s["server_alive"] == want;
  };
  ASSERT_TRUE(c.wait_until([&] { return alive(true); }, 5));
  const int generation = c.last_text("topology")["generation"];
  server.reset();  // gone: its writers' liveliness ends
  ASSERT_TRUE(c.wait_until([&] { return alive(false); }, 5)) << bridge.child().log();
  EXPECT_EQ(c.last_text("status")["server"]["scene"], "test_scene");  // the last status is kept
  server = std::make_unique<wt::FakeServer>(o);
  ASSERT_TRUE(c.wait_until([&] { return alive(true); }, 10)) << bridge.child().log();
  ASSERT_TRUE(c.wait_until([&] { return c.last_text("topology")["generation"] > generation; }, 10));
  const std::size_t before = c.frames();
  EXPECT_TRUE(c.wait_until([&] { return c.frames() >= before + 10; }, 10));
  EXPECT_EQ(check_decoding(c.messages()).undecodable, 0U);
  const std::string log = bridge.child().log();
  EXPECT_NE(log.find("server gone"), std::string::npos);
  EXPECT_NE(log.find("server seen"), std::string::npos);
}
