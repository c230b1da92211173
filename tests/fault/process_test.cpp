// Faults of the processes around a session, on loopback, each bounded in time: the server killed
// (SIGKILL) mid-contact and restarted, the server stopped (SIGSTOP) for 2 s and continued, a
// station process killed mid-contact, a viewer joining and leaving 50 times. The haptic stations
// are the real client (DdsLink + HapticLoop) in this process, holding a scripted tool in the
// cube; the server is the real neurosim-server in its own process with a topic prefix of its own.
#include "fault/fault_session.hpp"

#include <gtest/gtest.h>
#include <signal.h>

using namespace neurosim::fault_testing;

TEST(fault_process, ServerKilledMidContactThenRestartedStationsResume) {
  Session s("fkill");
  auto server = s.start_server("server1.log");
  Station a(s, "a", 0.035, 0.003, 60), b(s, "b", 0.065, 0.003, 60);
  ASSERT_TRUE(a.pressing(0.5, *server));
  ASSERT_TRUE(b.pressing(0.5, *server));
  sleep_s(0.5);  // past the ramp-in
  const double fa = a.force(), fb = b.force();
  const std::size_t kill_a = a.ticks(), kill_b = b.ticks();
  server->signal_and_wait(SIGKILL, 5);
  sleep_s(1.0);
  EXPECT_EQ(a.force(), 0.0);
  EXPECT_EQ(b.force(), 0.0);

  // The same scene again; the stations were not restarted.
  auto again = s.start_server("server2.log");
  const bool back = a.wait_force_at_least(0.9 * fa, 60) && b.wait_force_at_least(0.9 * fb, 60);
  sleep_s(0.3);
  a.join();
  b.join();
  EXPECT_TRUE(back) << "forces after the restart " << a.force() << " N, " << b.force()
                    << " N (before " << fa << ", " << fb << ")\n"
                    << again->log();
  for (const Station* st : {&a, &b}) {
    const double outlived = force_outlived_ms(st->trace(), st == &a ? kill_a : kill_b);
    const double limit_ms = 1e3 * st->config().force.model_timeout_s + 20;
    std::printf("force outlived the newest model by %.1f ms (limit %.0f); max step %.3f N\n",
                outlived, limit_ms, st->max_force_step());
    EXPECT_GT(outlived, 0);
    EXPECT_LE(outlived, limit_ms);
    EXPECT_LE(st->max_force_step(), st->config().force.max_force_step_n + 1e-12)
        << "the force jumped (at the kill or when the restarted server answered)";
  }
}

TEST(fault_process, ServerStoppedTwoSecondsThenContinuedStationKeepsItsSlot) {
  OneStation t("fstop", 0.05, 0.004, 60);
  auto& [s, server, status, a] = t;
  ASSERT_TRUE(a.pressing(0.5, *server));
  sleep_s(0.5);
  const double f_before = a.force();
  const std::size_t stop_tick = a.ticks();
  ASSERT_EQ(::kill(server->pid(), SIGSTOP), 0);
  sleep_s(2.0);
  EXPECT_EQ(a.force(), 0.0) << "the force did not fade while the server was stopped";
  const std::uint64_t models_at_cont = a.counters().models_received;
  ASSERT_EQ(::kill(server->pid(), SIGCONT), 0);
  sleep_s(0.3);
  const std::uint64_t models_300ms = a.counters().models_received - models_at_cont;
  EXPECT_TRUE(a.wait_force_at_least(0.9 * f_before, 5)) << a.force() << " of " << f_before;
  sleep_s(0.3);
  a.join();

  // After the first fresh model (one answering a sample sent after the stop), the force comes
  // back to 90 % through the ramp-in.
  const auto& tr = a.trace();
  std::uint64_t seq_at_stop = 0;
  for (std::size_t i = 0; i < stop_tick && i < tr.size(); ++i)
    seq_at_stop = std::max(seq_at_stop, tr[i].model_sequence);
  std::size_t fresh = 0, full = 0;
  for (std::size_t i = stop_tick; i < tr.size(); ++i)
    if (tr[i].model_sequence > seq_at_stop + 1000) {  // sent more than 1 s after the stop
      fresh = i;
      break;
    }
  ASSERT_GT(fresh, 0u) << "no fresh model after the server continued";
  for (std::size_t i = fresh; i < tr.size(); ++i)
    if (tr[i].force_n.norm() >= 0.9 * f_before) {
      full = i;
      break;
    }
  ASSERT_GT(full, 0u);
  const double back_s = 1e-9 * static_cast<double>(tr[full].now_ns - tr[fresh].now_ns);
  std::printf("force back to 90 %% %.3f s after the first fresh model; %llu models in the 300 ms "
              "after SIGCONT; max step %.3f N\n",
              back_s, static_cast<unsigned long long>(models_300ms), a.max_force_step());
  // Back through the ramp-in, not in one jump (how long it takes is printed only: a loaded
  // machine delays the models and the ticks that carry it, without any fault).
  EXPECT_GT(back_s, 0.0);
  EXPECT_LT(tr[fresh].force_n.norm(), 0.9 * f_before);
  EXPECT_LE(a.max_force_step(), a.config().force.max_force_step_n + 1e-12);
  // No burst: the stalled schedule restarts instead of replaying 2000 missed steps.
  EXPECT_LE(models_300ms, 450u);
  // The station kept its slot: one entry, nobody refused.
  ASSERT_TRUE(status.wait_for(
      [](const neurosim_SimStatus& st) {
        return neurosim::service::testing::find_station(st, "a") != nullptr;
      },
      5))
      << status.text;
  EXPECT_EQ(status.refused, 0u) << status.text;
  server->signal_and_wait(SIGTERM, 10);
}

TEST(fault_process, StationKilledMidContactIsDroppedAndTheOtherFeelsOnlyThePhysics) {
  // Phase 1: station a alone; 2: a killable station process presses beside it; 3: that process
  // is killed. a's force in phase 3 must return to its phase-1 value (the physics of the removed
  // tool), the server must drop the killed station's contact, and a's force never jumps.
  OneStation t("fstation", 0.035, 0.0002, 60);  // 0.2 mm: well below the device's force clamp
  auto& [s, server, status, a] = t;
  ASSERT_TRUE(a.pressing(0.2, *server));
  sleep_s(0.7);
  const double f_alone = a.force();
  ASSERT_LT(f_alone, 0.8 * a.config().force.max_force_n) << "clamped: the physics is not seen";

  // The other station: neurosim-haptic in its own process, stroking 2 mm deep at y = 0.065.
  ChildProcess other(neurosim::testing::bin_dir() / "neurosim-haptic",
                     {"--station", "ghost", "--device", "script:stroke", "--duration", "30",
                      "--no-rt", "--origin", "0.1,0.065,0.05", "--up", "1,0,0", "--topic-prefix",
                      s.prefix},
                     s.dir / "ghost.log");
  ASSERT_TRUE(status.wait_for(
      [](const neurosim_SimStatus& st) {
        const auto* g = neurosim::service::testing::find_station(st, "ghost");
        return g != nullptr && g->in_contact;
      },
      20))
      << status.text << "\n" << other.log();
  sleep_s(0.5);
  const double f_with = a.force();
  EXPECT_EQ(other.signal_and_wait(SIGKILL, 5), 128 + SIGKILL);
  const auto killed = Clock::now();
  const bool dropped = status.wait_for(
      [](const neurosim_SimStatus& st) {
        const auto* g = neurosim::service::testing::find_station(st, "ghost");
        return g == nullptr || !g->in_contact;
      },
      15);
  const double dropped_s = seconds_since(killed);
  // a's force back at its value alone (the model answering a's pose without the other tool);
  // polled, not read after a fixed wait: a loaded machine takes longer to get there.
  double f_after = a.force();
  for (const auto t0 = Clock::now();
       std::abs(f_after - f_alone) > 0.02 * f_alone + 1e-3 && seconds_since(t0) < 10;
       f_after = a.force())
    sleep_s(0.05);
  a.join();
  std::printf("a alone %.4f N, with the other tool %.4f N, after its kill %.4f N; contact dropped "
              "%.2f s after the kill\n",
              f_alone, f_with, f_after, dropped_s);
  // Dropped (liveliness lease 0.5 s, status at 1 Hz: about 1.5 s on an idle machine, printed
  // above; no time bound asserted, a loaded machine delays both).
  EXPECT_TRUE(dropped) << status.text;
  EXPECT_NEAR(f_after, f_alone, 0.02 * f_alone + 1e-3);
  EXPECT_LE(a.max_force_step(), a.config().force.max_force_step_n + 1e-12);
  EXPECT_EQ(status.refused, 0u);
  server->signal_and_wait(SIGTERM, 10);
}

TEST(fault_process, ViewerJoiningAndLeaving50TimesLeavesNoTrace) {
  OneStation t("fviewer", 0.05, 0.003, 120);
  auto& [s, server, status, a] = t;
  ASSERT_TRUE(a.pressing(0.5, *server));

  // One viewer: a participant of its own with the viewer's readers, until it has a frame, then
  // `stay` (called until it returns true or 15 s have passed: room for a loaded machine).
  auto viewer_visit = [prefix = s.prefix](const std::function<bool()>& stay = [] { return true; }) {
    wire::Participant pp;
    wire::Topic<neurosim_MeshTopology> topo(pp, wire::topic_name<neurosim_MeshTopology>(prefix));
    wire::Topic<neurosim_Deformation> def(pp, wire::topic_name<neurosim_Deformation>(prefix));
    wire::Reader<neurosim_MeshTopology> topo_reader(pp, topo);
    wire::Reader<neurosim_Deformation> def_reader(pp, def);
    const auto t0 = Clock::now();
    bool topology = false, frame = false;
    while (!(topology && frame) && seconds_since(t0) < 15) {
      for (const auto& rx : topo_reader.take()) topology |= rx.valid();
      for (const auto& rx : def_reader.take()) frame |= rx.valid();
      sleep_s(0.01);
    }
    while (!stay() && seconds_since(t0) < 15) sleep_s(0.01);
    return topology && frame;
  };
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(viewer_visit()) << server->log();  // warm-up
  // While a viewer is there the server solves displacement fields for it and measures their
  // strain (SimStatus max_strain >= 0); with none, it solves none (max_strain -1). The visit
  // stays until a status says so.
  bool measured = false;
  ASSERT_TRUE(viewer_visit([&] {
    return measured = status.wait_for([](const neurosim_SimStatus& st) { return st.max_strain >= 0; }, 0.2);
  }));
  EXPECT_TRUE(measured) << "no field strain measured while a viewer was there: " << status.text;
  sleep_s(2.5);  // two status periods without a viewer
  ASSERT_TRUE(status.wait_for([](const neurosim_SimStatus&) { return true; }, 3));
  const long rss_before = neurosim::common::resident_kib(server->pid());
  const double p99_before = status.p99_us;
  int visits = 0;
  for (int i = 0; i < 50; ++i) visits += viewer_visit() ? 1 : 0;
  sleep_s(2.5);
  // The viewers gone, the server stops the field work they caused (not measured by the step's
  // time: load alone changes that; the step p99 is printed only).
  const bool fields_stopped =
      status.wait_for([](const neurosim_SimStatus& st) { return st.max_strain < 0; }, 5);
  const long rss_after = neurosim::common::resident_kib(server->pid());
  const double p99_after = status.p99_us;
  a.join();
  std::printf("50 viewer visits (%d saw a frame): server RSS %ld -> %ld kB, step p99 %.0f -> %.0f us\n",
              visits, rss_before, rss_after, p99_before, p99_after);
  EXPECT_EQ(visits, 50);
  EXPECT_TRUE(fields_stopped) << "fields still solved after the viewers left: " << status.text;
  ASSERT_GT(rss_before, 0);
  // Growth allowed: allocator noise, not a leak per visit (50 visits x 100 kB would be 5 MB).
  EXPECT_LE(rss_after - rss_before, 2048) << "server memory grew with viewers that left";
  server->signal_and_wait(SIGTERM, 10);
}

// A second neurosim-haptic with a station id another writer holds: the server refuses it
// (identity: its samples rejected and counted) and the client says so at once, not at exit, and ends with status 3; the station
// holding the id goes on.
TEST(fault_process, StationUnderAnIdHeldByAnotherIsToldAtOnceAndExitsThree) {
  OneStation t("frefused", 0.05, 0.001, 60);
  auto& [s, server, status, a] = t;
  ASSERT_TRUE(a.pressing(0.1, *server));
  const auto started = Clock::now();
  ChildProcess twin(neurosim::testing::bin_dir() / "neurosim-haptic",
                    {"--station", "a", "--device", "script:press", "--duration", "30", "--no-rt",
                     "--origin", "0.1,0.02,0.05", "--up", "1,0,0", "--topic-prefix", s.prefix},
                    s.dir / "twin.log");
  const int rc = twin.wait(28);
  const double took_s = seconds_since(started);
  const std::string log = twin.log();
  std::printf("twin of station 'a': exit %d after %.2f s\n", rc, took_s);
  EXPECT_EQ(rc, 3) << log;
  // Bound with room for a loaded machine (start-up and discovery slow down), still well before
  // the end of the 30 s session.
  EXPECT_LT(took_s, 20.0) << "said at once, not at the end of its 30 s session";
  EXPECT_NE(log.find("error: station 'a' refused by the server"), std::string::npos) << log;
  EXPECT_NE(log.find("exiting"), std::string::npos) << log;
  ASSERT_TRUE(status.wait_for(
      [](const neurosim_SimStatus& st) { return st.samples_rejected_identity > 0; }, 5))
      << status.text;
  sleep_s(0.5);
  const double f = a.force();
  a.join();
  EXPECT_GT(f, 0.1) << "the station holding the id keeps its force";
  server->signal_and_wait(SIGTERM, 10);
}
