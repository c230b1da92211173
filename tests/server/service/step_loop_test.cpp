// StepLoop::step_once without DDS traffic: stations admitted from samples as the reader hands
// them over, the step on a small Simulation whose step throws for a poisoned tip, ContactModels
// recorded (service_parts_fixtures.hpp).
#include "server/service/step_loop.hpp"

#include "tests/server/service/service_parts_fixtures.hpp"

#include <gtest/gtest.h>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace {

using namespace neurosim::service;
using neurosim::service::testing::FakeDirectory;
using neurosim::service::testing::PoisonSimulation;
using neurosim::service::testing::RecordingSink;
using neurosim::service::testing::SampleIn;

constexpr std::int64_t kSecond = 1000000000;

struct Loop {
  Loop() {
    stations.set_directory(&directory);
    StepLoopDef def;
    def.step_failure_holdoff_ns = 1000 * kSecond;  // a reset station stays out for the whole test
    loop.emplace(def, sim, stations, sink, [this](const std::string& l) { log.push_back(l); });
  }
  // A pose of `station` (its own writer and participant), handed to its slot.
  void pose(const std::string& station, std::uint64_t seq, double x_m) {
    auto it = writer_of.find(station);
    if (it == writer_of.end()) {
      it = writer_of.emplace(station, static_cast<dds_instance_handle_t>(100 + writer_of.size())).first;
      directory.add(it->second, station, static_cast<int>(it->second));
    }
    const dds_instance_handle_t h = it->second;
    const std::int64_t t = 10 * kSecond + static_cast<std::int64_t>(seq) * 1000000;
    const SampleIn s(h, station, seq, x_m, t);
    stations.handle(s.rx(), ReceiveTime{t, t});
  }
  std::vector<neurosim::service::testing::ModelOut> models_of(const std::string& station) const {
    std::vector<neurosim::service::testing::ModelOut> out;
    for (const auto& m : sink.written)
      if (m.station_id == station) out.push_back(m);
    return out;
  }
  std::map<std::string, dds_instance_handle_t> writer_of;
  FakeDirectory directory;
  StationAdmission stations{StationAdmissionDef{}, nullptr};
  PoisonSimulation sim;
  RecordingSink sink;
  std::vector<std::string> log;
  std::optional<StepLoop> loop;
};

TEST(service_step_loop, EveryStationWithAPoseGetsItsContactModel) {
  Loop t;
  t.pose("a", 1, -0.001);
  t.pose("b", 1, 0.2);
  t.loop->step_once();
  ASSERT_EQ(t.models_of("a").size(), 1u);
  ASSERT_EQ(t.models_of("b").size(), 1u);
  EXPECT_TRUE(t.models_of("a")[0].in_contact);
  EXPECT_NEAR(t.models_of("a")[0].f0_x_n, 1.0, 1e-12);  // k * 1 mm
  EXPECT_FALSE(t.models_of("b")[0].in_contact);
  EXPECT_EQ(t.loop->counters().steps.load(), 1u);
  EXPECT_EQ(t.sim.calls, 1) << "one step for all stations";
  // Viscoelastic answers: the relaxing parts of f0 with their times, none out of contact.
  const auto a = t.models_of("a")[0].relaxing;
  ASSERT_EQ(a.size(), 2u);
  EXPECT_NEAR(a[0][0], 0.4, 1e-12);
  EXPECT_EQ(a[0][1], 0.5);
  EXPECT_NEAR(a[1][0], 0.2, 1e-12);
  EXPECT_EQ(a[1][1], 50.0);
  EXPECT_TRUE(t.models_of("b")[0].relaxing.empty());
}

// A step that throws for one station's pose: that station is reset (zero force, flagged
// rejected, not stepped again during the hold-off), the others are answered in the same step
// and in the next ones.
TEST(service_step_loop, AStepFailureForOneStationsPoseResetsThatStationOnly) {
  Loop t;
  t.pose("good-1", 1, -0.001);
  t.pose("bad", 1, PoisonSimulation::kPoisonX + 0.5);
  t.pose("good-2", 1, -0.002);
  ASSERT_NO_THROW(t.loop->step_once());
  EXPECT_EQ(t.loop->counters().step_failures.load(), 1u);
  ASSERT_EQ(t.models_of("bad").size(), 1u);
  EXPECT_TRUE(t.models_of("bad")[0].rejected);
  EXPECT_FALSE(t.models_of("bad")[0].in_contact);
  EXPECT_EQ(t.models_of("bad")[0].f0_x_n, 0.0);
  ASSERT_EQ(t.models_of("good-1").size(), 1u);
  ASSERT_EQ(t.models_of("good-2").size(), 1u);
  EXPECT_NEAR(t.models_of("good-1")[0].f0_x_n, 1.0, 1e-12);
  EXPECT_NEAR(t.models_of("good-2")[0].f0_x_n, 2.0, 1e-12);
  EXPECT_FALSE(t.models_of("good-1")[0].rejected);
  bool named = false;
  for (const auto& l : t.log) named = named || l.find("station 'bad'") != std::string::npos;
  EXPECT_TRUE(named) << "the log names the station whose pose failed";
  // Next steps: the good stations are served, the reset one is held out.
  t.pose("good-1", 2, -0.003);
  t.pose("bad", 2, PoisonSimulation::kPoisonX + 0.5);
  const int calls = t.sim.calls;
  t.loop->step_once();
  EXPECT_EQ(t.sim.calls, calls + 1) << "no second containment: the reset station is held out";
  EXPECT_EQ(t.models_of("good-1").size(), 2u);
  EXPECT_EQ(t.models_of("good-2").size(), 2u);
  EXPECT_EQ(t.models_of("bad").size(), 1u);
  EXPECT_EQ(t.loop->counters().step_failures.load(), 1u);
}

TEST(service_step_loop, ALoneStationWhosePoseFailsIsResetAndTheLoopGoesOn) {
  Loop t;
  t.pose("bad", 1, PoisonSimulation::kPoisonX + 0.5);
  ASSERT_NO_THROW(t.loop->step_once());
  ASSERT_EQ(t.models_of("bad").size(), 1u);
  EXPECT_TRUE(t.models_of("bad")[0].rejected);
  EXPECT_EQ(t.loop->counters().steps.load(), 1u);
  ASSERT_NO_THROW(t.loop->step_once());
  EXPECT_EQ(t.loop->counters().steps.load(), 2u);
}

TEST(service_step_loop, ALeavingStationIsDisposedAndItsSlotFreed) {
  Loop t;
  t.pose("a", 1, -0.001);
  t.loop->step_once();
  t.stations.slots()[0].state.store(kSlotLeaving);
  t.loop->step_once();
  ASSERT_EQ(t.sink.disposed.size(), 1u);
  EXPECT_EQ(t.sink.disposed[0], "a");
  EXPECT_EQ(t.stations.slots()[0].state.load(), kSlotFree);
}

TEST(service_step_loop, BadDefinitionsAreRefused) {
  StepLoopDef d;
  d.max_step_rate_factor = 0.5;
  EXPECT_THROW(d.validate(), std::invalid_argument);
  d = StepLoopDef{};
  d.period_ns = 10;
  EXPECT_THROW(d.validate(), std::invalid_argument);
}

}  // namespace
