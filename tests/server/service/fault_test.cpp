// Hostile DDS input against the real server code (service_test_fake_server, a private domain):
// an attacker process (service_test_attacker) sends NaN/inf, 1e30 coordinates, zero quaternions,
// future timestamps, backwards sequence numbers, 20 kHz, a spoof of the legitimate station's id
// (bound writer and partition claim), a station beyond its participant's limit, an idle station
// and a flood of distinct ids, while a legitimate scripted station presses the box. Every cause
// must be counted in SimStatus, the legitimate station keeps its slot, its ContactModels keep
// coming at an unchanged force, the server's memory stays bounded. Station ids of 10 kB (a
// participant declaring the type with unbounded ids) never reach the server. Reordered samples
// are rejected as late and no answer goes back. One participant's 300 writers leave room for
// the next station. Also: SIGTERM during the real server's load ends it at once with a message
// naming the phase.
#include "common/process_stats.hpp"
#include "server/scene/compile.hpp"
#include "tests/server/service/fake_simulation.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <regex>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace wire = neurosim::wire;

namespace {

// fake_box.scene with room for 8 stations (the legitimate one, two of the attacker's, ...).
std::filesystem::path scene_with_8_stations() {
  const auto src = nt::source_dir() / "tests/server/service/data/fake_box.scene";
  std::string text = nt::slurp(src);
  text = std::regex_replace(text, std::regex("max_stations: 2"), "max_stations: 8");
  const auto dst = nt::temp_dir("service_fault_scene") / "fake_box_8.scene";
  std::ofstream(dst) << text;
  return dst;
}

st::Setup fake_setup(const std::filesystem::path& scene) {
  st::Setup s;
  s.exe = nt::bin_dir() / "service_test_fake_server";
  s.scene = scene;
  s.make_reference = [scene] { return st::make_fake(neurosim::scene::load_model(scene)); };
  s.startup_timeout_s = 20;
  return s;
}

// The server and the legitimate station "legit-1" pressing the box 2 mm deep for `seconds`
// (`setup` must outlive it: the session keeps a reference). Optionally going deeper at
// `deeper_m_per_s` and with every `hold_every`-th sample reordered (StationThread).
struct LegitSession {
  LegitSession(const st::Setup& setup, const std::string& tag, double seconds,
               double deeper_m_per_s = 0, std::uint64_t hold_every = 0)
      : ses(setup, tag, 40),
        models(ses.client),
        press{setup.face_x_m + setup.tip_radius_m - 0.002, setup.centre_y_m, setup.centre_z_m},
        legit(ses.client, "legit-1",
              [p = press, deeper_m_per_s](double t) {
                return std::array<double, 3>{p[0] - deeper_m_per_s * t, p[1], p[2]};
              },
              seconds, hold_every) {}
  // Serving, and the station's first 200 models in.
  ::testing::AssertionResult wait_pressing() {
    if (auto ready = ses.wait_ready(); !ready) return ready;
    if (!legit.writer().wait_for_readers(1, DDS_SECS(10)) ||
        !models.wait_for([&] { return models.count("legit-1") > 200; }, 10))
      return ::testing::AssertionFailure() << "no models for legit-1:\n" << ses.server.log();
    return ::testing::AssertionSuccess();
  }
  st::Session ses;
  st::ModelCollector models;
  std::array<double, 3> press;
  st::StationThread legit;
};


}  // namespace

TEST(service_fault, HostileSamplesAreCountedPerCauseAndTheLegitimateStationIsUnaffected) {
  const st::Setup setup = fake_setup(scene_with_8_stations());
  LegitSession session(setup, "fault", 30);
  ASSERT_TRUE(session.wait_pressing());
  auto& ses = session.ses;
  auto& models = session.models;
  auto& legit = session.legit;
  // The reference force: the first models at the held pose (all equal: a deterministic spring).
  const auto first = [&] {
    for (const auto& r : models.records())
      if (r.station == "legit-1" && r.in_contact) return r;
    return st::ModelRecord{};
  }();
  ASSERT_TRUE(first.in_contact) << "the legitimate station must press the box";
  // The legitimate station's model rate without the attacker, on this machine under its
  // present load: what the rate under attack is compared with (a fixed bound on gaps would fail
  // on a loaded machine with no attacker at all).
  const auto rate_over = [&](double seconds, const std::function<bool()>& go_on) {
    const std::size_t n0 = models.count("legit-1");
    const auto t0 = st::Clock::now();
    while (go_on() && st::seconds_since(t0) < seconds)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    return static_cast<double>(models.count("legit-1") - n0) / st::seconds_since(t0);
  };
  const double baseline_hz = rate_over(3.0, [] { return true; });
  const long rss_before = neurosim::common::resident_kib(ses.server.pid());
  const std::size_t models_before = models.count("legit-1");

  // Safe position of the attacker's own station: 5 cm outside the +x face (no contact).
  const int flood = 20000;
  st::ChildProcess attacker(nt::bin_dir() / "service_test_attacker",
                            {std::to_string(ses.domain), "legit-1", std::to_string(setup.face_x_m + 0.05),
                             std::to_string(setup.centre_y_m), std::to_string(setup.centre_z_m),
                             std::to_string(flood)},
                            ses.log_file.parent_path() / "attacker.log");
  // While it attacks, the legitimate station's models keep coming at a rate comparable to the
  // one before (the attacker's flood costs the server some CPU on these 2 cores; a server that
  // stopped serving legit-1 would fall to ~0). No fixed count: how many models a loaded machine
  // delivers in a few seconds is not the attacker's doing.
  // The spoof's refusal is looked for in every status during the attack: the server keeps the 16
  // newest refusals for 5 s, so the id flood at the attack's end (or a slow poll afterwards) pushes
  // legit-1's out of SimStatus.refused.
  bool refusal_seen = false;
  const auto note_refusal = [&](const neurosim_SimStatus& s) {
    for (const auto& r : wire::view(s.refused))
      if (std::string(r.station_id) == "legit-1" && r.reason == neurosim_REFUSED_IDENTITY) refusal_seen = true;
  };
  const double attack_hz = rate_over(20.0, [&] {
    ses.status.wait_for([&](const neurosim_SimStatus& s) { return note_refusal(s), false; }, 0.05);
    return attacker.alive();
  });
  EXPECT_EQ(attacker.wait(10), 0) << attacker.log();
  std::printf("legit-1 models per second: %.0f before the attack, %.0f during it\n", baseline_hz,
              attack_hz);
  // A quarter: the load of a parallel suite varies between the two windows too; a starved
  // station falls to ~0.
  EXPECT_GT(attack_hz, 0.25 * baseline_hz) << "the attacker starved the legitimate station";
  // Every cause counted; the idle attacker station reclaimed after the 2 s timeout. The rate
  // limit's count is only asked to be non-zero: of evil-1's 0.5 s at 20 kHz the server sees what
  // its best-effort keep-last-1 reader holds when it takes (a loaded machine delays the reader and
  // the burst overwrites itself: 897 rejections were seen beside stress-ng, of at most 9000 the
  // burst can give); without the limit it stays 0.
  const bool counted = ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        note_refusal(s);
        const auto* l = st::find_station(s, "legit-1");
        return s.samples_rejected_nonfinite > 0 && s.samples_rejected_workspace > 0 &&
               s.samples_rejected_time > 0 && s.samples_rejected_sequence > 0 &&
               s.samples_rejected_identity > static_cast<std::uint64_t>(flood) / 2 &&
               s.samples_rejected_rate > 0 && s.stations_refused >= 1 && s.stations_reclaimed >= 1 &&
               l != nullptr && l->samples_rejected_identity > 0 && st::find_station(s, "evil-2") == nullptr;
      },
      10);
  EXPECT_TRUE(counted) << ses.status.last_text << "\n" << ses.server.log();
  EXPECT_TRUE(refusal_seen) << "SimStatus.refused never named the spoofing writer of legit-1";
  // The legitimate station: still in its slot, none of its own samples rejected.
  EXPECT_TRUE(ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        const auto* l = st::find_station(s, "legit-1");
        return l != nullptr && l->samples_rejected_nonfinite == 0 && l->samples_rejected_jump == 0 &&
               l->samples_rejected_workspace == 0 && l->samples_rejected_time == 0 &&
               l->samples_rejected_sequence == 0 && l->samples_accepted > 1000;
      },
      5))
      << ses.status.last_text;
  // Its force never moved: every model answers its own pose (the spoof was 5 mm deeper).
  std::size_t compared = 0;
  for (const auto& r : models.records()) {
    if (r.station != "legit-1") continue;
    ASSERT_TRUE(r.in_contact) << "seq " << r.tool_sequence;
    ASSERT_FALSE(r.rejected) << "seq " << r.tool_sequence;
    ASSERT_LT(r.tool_sequence, 1000000u) << "a model answers the spoofer's pose";
    EXPECT_TRUE(st::near_rel(r.f0, first.f0, 3, 1e-12, 1e-9)) << "seq " << r.tool_sequence;
    ++compared;
  }
  EXPECT_GT(models.count("legit-1"), models_before) << "no model for legit-1 during the attack";
  // Memory: the flood of distinct ids grows the server by far less than the 73 MB seen before.
  const long rss_after = neurosim::common::resident_kib(ses.server.pid());
  EXPECT_LT(rss_after - rss_before, 16 * 1024) << "RSS " << rss_before << " kB -> " << rss_after << " kB";
  // The log is rate limited: a few lines per cause per second, not one per sample.
  const std::string log = ses.server.log();
  const auto lines = std::count(log.begin(), log.end(), '\n');
  EXPECT_LT(lines, 1000) << "log lines " << lines;
  EXPECT_NE(log.find("suppressed"), std::string::npos);
  std::printf("fault: %zu legit models compared, RSS %ld -> %ld kB, %ld log lines\n%s\n", compared, rss_before,
              rss_after, static_cast<long>(lines), ses.status.last_text.c_str());
  legit.join();
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
}

// Reordering on the wire (loopback neither reorders nor can be made to here: no netem in this
// kernel, and Cyclone's fault injection only drops): the station writes every 4th sample after
// its successor, as a reordering network would deliver it, while pressing deeper at 1 mm/s. A
// late sample that comes after the server took its successor is rejected as `sequence` (never as
// a jump); one that comes before replaces its successor in the reader's keep-last-1 history (the
// server answers a 1 ms older pose, and the successor is lost). Either way the answers never go
// back: their tool sequence never falls and neither does the force on a path that only goes deeper.
TEST(service_fault, ReorderedToolStatesAreDroppedAndNoAnswerGoesBack) {
  const st::Setup setup = fake_setup(scene_with_8_stations());
  const std::uint64_t hold_every = 4;
  LegitSession session(setup, "fault_reorder", 4, 0.001, hold_every);
  ASSERT_TRUE(session.wait_pressing());
  auto& ses = session.ses;
  session.legit.wait_done();
  const std::uint64_t sent = session.legit.sent_count();
  const std::uint64_t late = (sent - 1) / hold_every;  // held and written after their successor
  // The station is reclaimed 2 s after its last sample: by then every sample is counted (the
  // server-wide counters keep them; the only station is this one).
  neurosim_SimStatus final{};
  const bool done = ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        final = s;
        return s.stations_reclaimed >= 1;
      },
      20);  // 2 s and a status period on an idle machine; room for a loaded one
  ASSERT_TRUE(done) << ses.status.last_text;
  std::printf("reordered: %llu sent, %llu late; rejected: sequence %llu, jump %llu\n",
              static_cast<unsigned long long>(sent), static_cast<unsigned long long>(late),
              static_cast<unsigned long long>(final.samples_rejected_sequence),
              static_cast<unsigned long long>(final.samples_rejected_jump));
  EXPECT_GT(final.samples_rejected_sequence, 0u) << "no late sample was seen late";
  EXPECT_LE(final.samples_rejected_sequence, late);
  EXPECT_EQ(final.samples_rejected_jump, 0u);
  EXPECT_EQ(final.samples_rejected_time, 0u);
  std::uint64_t last_seq = 0;
  double last_force = 0;
  std::size_t answers = 0;
  for (const auto& r : session.models.records()) {
    if (r.station != "legit-1" || r.tool_sequence == 0) continue;
    ASSERT_GE(r.tool_sequence, last_seq) << "an answer went back";  // a step with no new sample repeats
    const double f = std::sqrt(r.f0[0] * r.f0[0] + r.f0[1] * r.f0[1] + r.f0[2] * r.f0[2]);
    ASSERT_GE(f, last_force * (1 - 1e-12)) << "the force fell at sequence " << r.tool_sequence;
    last_seq = r.tool_sequence;
    last_force = f;
    ++answers;
  }
  // Enough answers for the order check to mean something: thousands on an idle machine, fewer on
  // a loaded one (the server answers the newest pose each step and steps less often), never a
  // handful. The late samples are the point: some reached the server late.
  std::printf("reordered: %zu answers\n", answers);
  EXPECT_GT(answers, 400u);
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
}

// Station ids of 10 kB. The real type bounds them (Id is string<64>), so a participant that
// wants to send one must declare the topic's type with unbounded ids
// (service_test_long_id_attacker). The server's ToolState reader is discovered by it (same topic
// and type name) but not matched (the types are not assignable), so none of its samples reaches
// the server: nothing to count in SimStatus, no slot, no log line, and the legitimate station
// is served throughout.
TEST(service_fault, StationIdsOfTenKilobytesNeverReachTheServer) {
  const st::Setup setup = fake_setup(scene_with_8_stations());  // outlives the session
  LegitSession session(setup, "fault_long_id", 20);
  ASSERT_TRUE(session.wait_pressing());
  auto& ses = session.ses;
  auto& models = session.models;
  auto& legit = session.legit;
  const std::size_t before = models.count("legit-1");
  st::ChildProcess attacker(nt::bin_dir() / "service_test_long_id_attacker",
                            {std::to_string(ses.domain), "10240", "3"},
                            ses.log_file.parent_path() / "long_id_attacker.log");
  ASSERT_EQ(attacker.wait(30), 0) << attacker.log();
  const std::string out = attacker.log();
  std::printf("%s", out.c_str());
  EXPECT_NE(out.find("server ToolState reader discovered: yes; readers matched: 0"), std::string::npos)
      << out;
  EXPECT_NE(out.find("wrote 3000 of 3000 samples with a 10240-byte station id"), std::string::npos)
      << out;
  EXPECT_GT(models.count("legit-1"), before + 2000) << "the legitimate station kept being served";
  // What a 10 kB id would cause, had any sample of the attacker reached the server: a slot for
  // it, a refusal naming it, or an identity rejection (its writer's partition claims "x", not
  // its id). None may be seen. Rejections of legit-1's own samples for rate, jump or sequence
  // (the only station: they can only be its own) are what a loaded machine can cause without
  // any attacker (a descheduled station thread writes its missed samples back to back): not the
  // attacker's doing, not asserted here (tool_filter_test covers the burst a station may send).
  ASSERT_TRUE(ses.status.wait_for([](const neurosim_SimStatus&) { return true; }, 5));
  neurosim_SimStatus last{};
  const bool clean = ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        last = s;
        return s.stations._length == 1 && st::find_station(s, "legit-1") != nullptr;
      },
      5);
  EXPECT_TRUE(clean) << "a station other than legit-1 holds a slot: " << ses.status.last_text;
  EXPECT_EQ(last.samples_rejected_identity, 0u) << ses.status.last_text;
  EXPECT_EQ(last.samples_rejected_nonfinite + last.samples_rejected_workspace +
                last.samples_rejected_time,
            0u)
      << ses.status.last_text;
  EXPECT_EQ(last.stations_refused, 0u) << ses.status.last_text;
  EXPECT_EQ(last.refused._length, 0u) << "a refusal was published: " << ses.status.last_text;
  std::printf("legit-1's own samples rejected meanwhile: rate %llu, jump %llu, sequence %llu\n",
              static_cast<unsigned long long>(last.samples_rejected_rate),
              static_cast<unsigned long long>(last.samples_rejected_jump),
              static_cast<unsigned long long>(last.samples_rejected_sequence));
  legit.join();
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
}

// One DDS participant with 300 ToolState writers, each in its own station's partition and each
// sending one sample, then going idle (what filled the server's 256-writer table, so a station
// that came next was ignored without a refusal): the server caches at most its per-participant
// limit of that participant's writers (the rest evict each other), gives it its limit of
// stations and refuses the others naming that limit, and a legitimate station of another
// participant joining afterwards is served and never refused. Real DDS on a private domain.
TEST(service_fault, ThreeHundredWritersOfOneParticipantLeaveRoomForTheNextStation) {
  const st::Setup setup = fake_setup(scene_with_8_stations());  // outlives the session
  st::Session ses(setup, "fault_writers", 60);
  ASSERT_TRUE(ses.wait_ready());
  // The squatter: a participant of its own, 1 cm outside the box's face (no contact).
  st::Client squatter(ses.domain);
  const double p[3] = {setup.face_x_m + setup.tip_radius_m + 0.01, setup.centre_y_m,
                       setup.centre_z_m};
  std::vector<std::unique_ptr<wire::Writer<neurosim_ToolState>>> writers;
  wire::Sample<neurosim_ToolState> sample;
  for (int w = 0; w < 300; ++w) {
    const std::string id = "squat-" + std::to_string(w);
    writers.push_back(
        std::make_unique<wire::Writer<neurosim_ToolState>>(squatter.pp, squatter.tool_topic, id));
  }
  for (int w = 0; w < 300; ++w) {
    ASSERT_TRUE(writers[static_cast<std::size_t>(w)]->wait_for_readers(1, DDS_SECS(20)))
        << "writer " << w << " never matched the server's reader";
    st::fill_tool(*sample, ("squat-" + std::to_string(w)).c_str(), 1, p, dds_time());
    writers[static_cast<std::size_t>(w)]->write(*sample);
  }
  // The server took the squatter's samples: its limit of stations, the rest refused.
  auto squat_stations = [](const neurosim_SimStatus& s) {
    std::size_t n = 0;
    for (const auto& x : wire::view(s.stations)) n += std::string(x.station_id).rfind("squat-", 0) == 0;
    return n;
  };
  std::size_t held = 0;
  ASSERT_TRUE(ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        held = squat_stations(s);
        return held > 0 && s.stations_refused > 0;
      },
      20))
      << ses.status.last_text;
  // The legitimate station, right after, from another participant.
  st::ModelCollector models(ses.client);
  const std::array<double, 3> press{setup.face_x_m + setup.tip_radius_m - 0.002, setup.centre_y_m,
                                    setup.centre_z_m};
  st::StationThread legit(ses.client, "legit-1", [press](double) { return press; }, 15);
  const bool served = models.wait_for([&] { return models.count("legit-1") > 200; }, 20);
  neurosim_SimStatus last{};
  bool refused_legit = false;
  const bool listed = ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        for (const auto& r : wire::view(s.refused)) refused_legit |= std::string(r.station_id) == "legit-1";
        last = s;
        return st::find_station(s, "legit-1") != nullptr;
      },
      10);
  std::printf("300 writers of one participant: it holds %zu stations, %llu joins refused; legit-1 "
              "served: %zu models\n",
              squat_stations(last), static_cast<unsigned long long>(last.stations_refused),
              models.count("legit-1"));
  EXPECT_TRUE(served) << "legit-1 got no models after the squatter's writers:\n" << ses.server.log();
  EXPECT_TRUE(listed) << ses.status.last_text;
  EXPECT_FALSE(refused_legit) << ses.status.last_text;
  EXPECT_LE(squat_stations(last), 2u) << "the squatter holds more than its participant's limit";
  legit.join();
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
}

// The real neurosim-server generating a 60,000-vertex cube (CGAL Mesh_3 and the compliance of
// that mesh: minutes on these machines) is told SIGTERM one second after it started: it ends
// at once (well under the 10 s allowed here, which a loaded machine needs at most to schedule
// the exit; the load itself would take minutes), status 0, naming the load phase it was in.
TEST(service_fault, SigtermDuringTheLoadEndsTheServerAtOnce) {
  std::string text = nt::slurp(nt::source_dir() / "scenes/cube_cylinder.scene");
  const std::string small = "target_vertices: 1812";
  ASSERT_NE(text.find(small), std::string::npos) << "cube_cylinder.scene changed its cube";
  text.replace(text.find(small), small.size(), "target_vertices: 60000");
  const auto dir = nt::temp_dir("service_fault_load");
  const auto scene = dir / "slow_cube.scene";
  std::ofstream(scene) << text;
  const std::string prefix = "fload" + std::to_string(::getpid()) + "_";
  st::ChildProcess server(nt::bin_dir() / "neurosim-server",
                          {"--scene", scene.string(), "--topic-prefix", prefix, "--duration", "60"},
                          dir / "server.log");
  std::this_thread::sleep_for(std::chrono::seconds(1));
  ASSERT_TRUE(server.alive()) << "the server ended before the signal:\n" << server.log();
  const auto t0 = st::Clock::now();
  EXPECT_EQ(server.signal_and_wait(SIGTERM, 10.0), 0) << server.log();
  const double took_s = st::seconds_since(t0);
  std::printf("ended %.3f s after SIGTERM\n", took_s);
  EXPECT_LT(took_s, 10.0);
  const std::string log = server.log();
  EXPECT_EQ(log.find("simulation built"), std::string::npos)
      << "the load was not slow enough to signal during it:\n" << log;
  EXPECT_TRUE(std::regex_search(
      log, std::regex("signal received while (loading the scene|building the simulation)[^\n]*"
                      ": exiting without serving")))
      << log;
}

// The real neurosim-server whose load takes longer than --load-timeout (a 30,000-vertex cube:
// tens of seconds of meshing) ends after the limit, status 1, naming the limit and the phase,
// without serving; a mesh file that is a named pipe no one writes to (it blocked the load for
// ever) is refused at once, naming it.
TEST(service_fault, LoadTimeoutAndANamedPipeMeshEndTheServersLoad) {
  const auto dir = nt::temp_dir("service_fault_load_limit");
  std::string text = nt::slurp(nt::source_dir() / "scenes/cube_cylinder.scene");
  const std::string small = "target_vertices: 1812";
  ASSERT_NE(text.find(small), std::string::npos) << "cube_cylinder.scene changed its cube";
  text.replace(text.find(small), small.size(), "target_vertices: 30000");
  const auto slow = dir / "slow_cube.scene";
  std::ofstream(slow) << text;
  const std::string prefix = "flimit" + std::to_string(::getpid()) + "_";
  {
    st::ChildProcess server(nt::bin_dir() / "neurosim-server",
                            {"--scene", slow.string(), "--topic-prefix", prefix, "--load-timeout", "1"},
                            dir / "slow.log");
    EXPECT_EQ(server.wait(60), 1) << server.log();
    const std::string log = server.log();
    EXPECT_NE(log.find("neurosim-server: error: the load took longer than 1 s (--load-timeout) while "),
              std::string::npos)
        << log;
    EXPECT_EQ(log.find("simulation built"), std::string::npos) << log;
  }
  ASSERT_EQ(::mkfifo((dir / "pipe.mesh").c_str(), 0600), 0);
  std::ofstream(dir / "fifo.scene") << "meshes { id: \"t\" file: \"pipe.mesh\"\n"
                                       "  material { youngs_modulus_pa: 1e6 poisson_ratio: 0.3 }\n"
                                       "  fixed { nodes { ids: 0 } } }\n";
  st::ChildProcess server(nt::bin_dir() / "neurosim-server",
                          {"--scene", (dir / "fifo.scene").string(), "--topic-prefix", prefix},
                          dir / "fifo.log");
  EXPECT_EQ(server.wait(60), 1) << server.log();
  EXPECT_NE(server.log().find((dir / "pipe.mesh").string() +
                              ": mesh file: is a named pipe, not a regular file"),
            std::string::npos)
      << server.log();
}

