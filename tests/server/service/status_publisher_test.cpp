// StatusPublisher without a writer: the sample it fills from the parts' counts, and when it is
// published (period, or early after a refusal).
#include "server/service/status_publisher.hpp"

#include "tests/server/service/service_parts_fixtures.hpp"

#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <vector>

namespace {

using namespace neurosim::service;
using neurosim::service::testing::FakeDirectory;
using neurosim::service::testing::PoisonSimulation;
using neurosim::service::testing::RecordingSink;
using neurosim::service::testing::SampleIn;

constexpr std::int64_t kMs = 1000000;
constexpr std::int64_t kSecond = 1000 * kMs;

struct Status {
  Status() {
    stations.set_directory(&directory);
    loop.emplace(StepLoopDef{}, sim, stations, sink, nullptr);
    settings.name = "fixture";
    StatusPublisherDef def;
    def.status_period_ns = kSecond;
    def.step_times_per_period = 200;
    status.emplace(def, settings, sim, stations, &*loop, nullptr, std::nullopt, nullptr,
                   [this](const std::string& line) { log.push_back(line); });
    status->begin(0);
  }
  void send(dds_instance_handle_t writer, const std::string& station, const std::string& claim, int participant) {
    directory.add(writer, claim, participant);
    const SampleIn s(writer, station, 1, 0.0, 10 * kSecond);
    stations.handle(s.rx(), ReceiveTime{10 * kSecond, 10 * kSecond});
  }
  neurosim::scene::Settings settings;
  FakeDirectory directory;
  StationAdmission stations{StationAdmissionDef{}, nullptr};
  PoisonSimulation sim;
  RecordingSink sink;
  std::optional<StepLoop> loop;
  std::optional<StatusPublisher> status;
  std::vector<std::string> log;  // the publisher's log lines
};

TEST(service_status_publisher, TheSampleCarriesTheStepsStationsAndStepTimes) {
  Status t;
  t.send(7, "omni-1", "omni-1", 1);
  t.loop->step_once();
  t.loop->step_once();
  t.sim.not_ready = 7;
  t.sim.solved_ahead = 1234;
  for (int us = 1; us <= 100; ++us) t.status->after_step(0, us * 1000);  // 1..100 us, within the period
  const neurosim_SimStatus& st = t.status->publish(2 * kSecond);
  EXPECT_EQ(st.columns_not_ready, 7u) << "the Simulation's count of columns not ready";
  EXPECT_EQ(st.columns_solved_ahead, 1234u);
  EXPECT_EQ(st.steps, 2u);
  EXPECT_DOUBLE_EQ(st.step_rate_measured_hz, 1.0) << "2 steps in 2 s";
  ASSERT_EQ(st.stations._length, 1u);
  EXPECT_STREQ(st.stations._buffer[0].station_id, "omni-1");
  EXPECT_EQ(st.stations._buffer[0].samples_accepted, 1u);
  EXPECT_DOUBLE_EQ(st.step_time_max_us, 100.0);
  EXPECT_NEAR(st.step_time_p50_us, 50.0, 1.0);
  EXPECT_NEAR(st.step_time_p99_us, 99.0, 1.0);
  EXPECT_EQ(st.max_strain, -1.0) << "no Deformation output: nothing measured";
  EXPECT_EQ(st.expected_force_error, -1.0) << "no accuracy table";
  EXPECT_EQ(st.discretization_error_estimate, -1.0) << "no discretization table";
  EXPECT_EQ(st.total_error_estimate, -1.0);
  EXPECT_EQ(st.refused._length, 0u);
}

// Steps that left touching contact rows out (beyond the per-tool limit) and steps whose contact
// LCP did not converge: published as the Simulation counts them, and logged once per status
// period in which they rose (naming the switch to raise), not again while they stay.
TEST(service_status_publisher, IncompleteContactStepsArePublishedAndLogged) {
  Status t;
  const neurosim_SimStatus& quiet = t.status->publish(kSecond);
  EXPECT_EQ(quiet.steps_with_rows_dropped, 0u);
  EXPECT_EQ(quiet.steps_not_converged, 0u);
  EXPECT_TRUE(t.log.empty());
  t.sim.rows_dropped = 3;
  t.sim.not_converged = 2;
  const neurosim_SimStatus& st = t.status->publish(2 * kSecond);
  EXPECT_EQ(st.steps_with_rows_dropped, 3u);
  EXPECT_EQ(st.steps_not_converged, 2u);
  ASSERT_EQ(t.log.size(), 2u);
  EXPECT_NE(t.log[0].find("3 step(s)"), std::string::npos) << t.log[0];
  EXPECT_NE(t.log[0].find("--contact-max-rows"), std::string::npos) << t.log[0];
  EXPECT_NE(t.log[1].find("2 step(s)"), std::string::npos) << t.log[1];
  EXPECT_NE(t.log[1].find("--lcp-max-iterations"), std::string::npos) << t.log[1];
  t.status->publish(3 * kSecond);
  EXPECT_EQ(t.log.size(), 2u) << "nothing new: nothing logged";
  t.sim.rows_dropped = 4;
  t.status->publish(4 * kSecond);
  ASSERT_EQ(t.log.size(), 3u);
  EXPECT_NE(t.log[2].find("1 step(s)"), std::string::npos) << t.log[2];
}

// The host's discretization error (looked up at set-up) is published as it is; the total needs
// the tier's part too: without a measured strain it stays unknown (-1), not the discretization
// part alone passed off as the total.
TEST(service_status_publisher, TheTotalErrorNeedsBothParts) {
  Status t;
  StatusPublisherDef def;
  def.discretization_error = 0.056;
  def.host_element = "smoothed-tet";
  def.host_poisson_ratio = 0.49;
  AccuracyTable table({{"fixture", neurosim::fem::Tier::kLinear, 0.5, 0.1, "smoothed-tet", 0.49}});
  StatusPublisher p(def, t.settings, t.sim, t.stations, &*t.loop, nullptr, table, nullptr, nullptr);
  p.begin(0);
  const neurosim_SimStatus& st = p.publish(kSecond);
  EXPECT_EQ(st.discretization_error_estimate, 0.056);
  EXPECT_EQ(st.max_strain, -1.0) << "no Deformation output: no strain";
  EXPECT_EQ(st.expected_force_error, -1.0);
  EXPECT_EQ(st.total_error_estimate, -1.0);
}

// A refused station is told at once: the next step at least 0.2 s after the last status
// publishes, with the refusal in it; without a refusal the status waits for its period.
TEST(service_status_publisher, ARefusalIsPublishedWithinAFifthOfASecond) {
  Status t;
  t.status->after_step(0, 300 * kMs);
  EXPECT_EQ(t.loop->counters().steps.load(), 0u);
  t.send(8, "omni-2", "omni-1", 2);  // claims another station than its partition: refused
  ASSERT_TRUE(t.stations.status_soon());
  t.status->after_step(300 * kMs, 310 * kMs);
  EXPECT_FALSE(t.stations.status_soon()) << "published at the first step after the refusal";
  const neurosim_SimStatus& st = t.status->publish(320 * kMs);
  ASSERT_EQ(st.refused._length, 1u);
  EXPECT_STREQ(st.refused._buffer[0].station_id, "omni-2");
  EXPECT_EQ(st.refused._buffer[0].reason, neurosim_REFUSED_IDENTITY);
  EXPECT_EQ(st.samples_rejected_identity, 1u);
  // Another refusal right after a status: it waits until 0.2 s have passed since that status.
  t.send(9, "omni-3", "omni-9", 3);
  t.status->after_step(320 * kMs, 330 * kMs);
  EXPECT_TRUE(t.stations.status_soon()) << "0.01 s after the last status: not yet";
  t.status->after_step(520 * kMs, 521 * kMs);
  EXPECT_FALSE(t.stations.status_soon());
}

}  // namespace

// A column cache bound below the tools' reach, which the column worker raised (column_worker.hpp):
// the server says so once per raise, naming the mesh, the bound, the nodes it was raised to and
// their memory; the same raise is not repeated every period, a larger one is logged again.
TEST(service_status_publisher, ARaisedColumnCacheBoundIsLoggedOncePerRaise) {
  Status t;
  t.sim.cache.capacity_slots = 100;
  t.sim.cache.bytes_per_slot = 250000;
  t.status->publish(kSecond);
  EXPECT_TRUE(t.log.empty()) << "nothing raised: " << t.log.front();
  t.sim.cache.raised_capacity_slots = 140;
  t.status->publish(2 * kSecond);
  ASSERT_EQ(t.log.size(), 1u);
  const std::string& w = t.log.front();
  EXPECT_EQ(w.rfind("warning: ", 0), 0u) << w;
  EXPECT_NE(w.find("'block'"), std::string::npos) << w;
  EXPECT_NE(w.find("bounded at 100 nodes"), std::string::npos) << w;
  EXPECT_NE(w.find("140 nodes within the column worker's reach"), std::string::npos) << w;
  EXPECT_NE(w.find("(35.0"), std::string::npos) << "140 x 250 kB = 35 MB: " << w;
  t.status->publish(3 * kSecond);
  EXPECT_EQ(t.log.size(), 1u) << "the same raise again: " << t.log.back();
  t.sim.cache.raised_capacity_slots = 180;
  t.status->publish(4 * kSecond);
  ASSERT_EQ(t.log.size(), 2u);
  EXPECT_NE(t.log.back().find("180 nodes"), std::string::npos) << t.log.back();
}
