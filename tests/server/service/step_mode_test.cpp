// The server's step modes (ServerOptions::step_mode) through the real server code with the fake
// physics (service_test_fake_server), each test on its own private DDS domain:
//   event: the step that answers a sample is started by the sample's arrival (the server counts
//          which wake-up started each step: a sample or the period deadline), and a station
//          sending faster than the scene rate cannot push the step rate past
//          --max-step-rate-factor × rates.step_hz;
//   clock: every step is started by the period deadline.
// No timing assertion that a busy CI machine can break: the counts are bounded by what was sent
// (each step on a sample takes at least one sample) and by the minimum gap between steps.
#include "server/scene/compile.hpp"
#include "tests/server/service/fake_simulation.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <regex>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;

namespace {

st::Setup fake_setup(const std::string& mode) {
  st::Setup s;
  s.exe = nt::bin_dir() / "service_test_fake_server";
  s.scene = nt::source_dir() / "tests/server/service/data/fake_box.scene";  // rates.step_hz 1000
  s.make_reference = [scene = s.scene] { return st::make_fake(neurosim::scene::load_model(scene)); };
  s.startup_timeout_s = 20;
  s.server_args = {"--step-mode", mode};
  return s;
}

struct StepCounts {
  long steps = -1, on_sample = -1, on_deadline = -1;
  std::string mode;
};

// From the server's last line: "stopped after N steps (...); MODE step mode: K steps on a sample,
// M on the deadline".
StepCounts step_counts(const std::string& log) {
  StepCounts c;
  std::smatch m;
  if (std::regex_search(log, m, std::regex("stopped after ([0-9]+) steps"))) c.steps = std::stol(m[1]);
  if (std::regex_search(log, m, std::regex("([a-z]+) step mode: ([0-9]+) steps on a sample, ([0-9]+) on the deadline"))) {
    c.mode = m[1];
    c.on_sample = std::stol(m[2]);
    c.on_deadline = std::stol(m[3]);
  }
  return c;
}

// Writes ToolStates for `station` at rate_hz (absolute deadlines) for seconds; returns how many.
std::uint64_t send(st::Client& c, const std::string& station, double rate_hz, double seconds) {
  neurosim::wire::Writer<neurosim_ToolState> w(c.pp, c.tool_topic, station);
  neurosim::wire::Sample<neurosim_ToolState> s;
  const double p[3] = {0.102, 0.05, 0.05};
  const auto period_ns = static_cast<std::int64_t>(1e9 / rate_hz);
  std::int64_t next = neurosim::common::monotonic_ns();
  const std::int64_t end = next + static_cast<std::int64_t>(seconds * 1e9);
  std::uint64_t seq = 0;
  while (next < end) {
    st::fill_tool(*s, station.c_str(), ++seq, p, dds_time());
    w.write(*s);
    next += period_ns;
    neurosim::common::sleep_until_ns(next);
  }
  return seq;
}

}  // namespace

TEST(service_step_mode, EventModeStepIsStartedByTheSampleItAnswers) {
  const auto setup = fake_setup("event");
  st::Session ses(setup, "step_event", 4.0);
  ASSERT_TRUE(ses.wait_ready());
  // 200 Hz: five step periods between samples, so the idle deadlines run in between and each
  // sample should find the step thread waiting.
  const std::uint64_t sent = send(ses.client, "slow", 200.0, 2.0);
  ASSERT_EQ(ses.server.wait(30), 0) << ses.server.log();
  const std::string log = ses.server.log();
  const StepCounts c = step_counts(log);
  ASSERT_EQ(c.mode, "event") << log;
  EXPECT_EQ(c.on_sample + c.on_deadline, c.steps) << log;
  // Each step on a sample took at least one (the semaphore counts the samples handed over).
  EXPECT_LE(c.on_sample, static_cast<long>(sent)) << log;
  // Most samples started their own step (two samples only share one after a 5 ms stall).
  EXPECT_GE(c.on_sample, static_cast<long>(sent) / 2) << "sent " << sent << "\n" << log;
  EXPECT_GT(c.on_deadline, 0) << "no sample: the period deadline must step\n" << log;
}

TEST(service_step_mode, FastStationsCannotPushTheStepRatePastTheLimit) {
  auto setup = fake_setup("event");
  setup.server_args.insert(setup.server_args.end(), {"--max-step-rate-factor", "1.5"});
  const double duration_s = 3.0;
  st::Session ses(setup, "step_fast", duration_s);
  ASSERT_TRUE(ses.wait_ready());
  // Two stations at 1.9 kHz each (under the per-station rate limit): 3.8 kHz of samples.
  std::uint64_t sent_b = 0;
  std::thread b([&] { sent_b = send(ses.client, "fast-b", 1900.0, duration_s); });
  const std::uint64_t sent_a = send(ses.client, "fast-a", 1900.0, duration_s);
  b.join();
  ASSERT_EQ(ses.server.wait(30), 0) << ses.server.log();
  const std::string log = ses.server.log();
  const StepCounts c = step_counts(log);
  ASSERT_EQ(c.mode, "event") << log;
  EXPECT_GT(c.on_sample, 0) << log;
  // Steps are at least 1 / (1.5 × 1000 Hz) apart, over at most the serving time (--duration
  // plus the shutdown): at most 1500 × (3 + 0.5) steps, while 3.8 kHz of samples came in.
  EXPECT_LE(c.steps, static_cast<long>(1500 * (duration_s + 0.5)))
      << "sent " << sent_a + sent_b << "\n" << log;
}

TEST(service_step_mode, ClockModeStepsOnlyOnTheDeadline) {
  const auto setup = fake_setup("clock");
  st::Session ses(setup, "step_clock", 3.0);
  ASSERT_TRUE(ses.wait_ready());
  send(ses.client, "slow", 200.0, 1.0);
  ASSERT_EQ(ses.server.wait(30), 0) << ses.server.log();
  const std::string log = ses.server.log();
  const StepCounts c = step_counts(log);
  ASSERT_EQ(c.mode, "clock") << log;
  EXPECT_EQ(c.on_sample, 0) << log;
  EXPECT_EQ(c.on_deadline, c.steps) << log;
  EXPECT_GT(c.steps, 0) << log;
}

TEST(service_step_mode, BadStepOptionsAreUsageErrors) {
  for (const std::vector<std::string>& bad :
       {std::vector<std::string>{"--step-mode", "tick"}, {"--rt-priority", "step=100"},
        {"--rt-priority", "stepper=10"}, {"--rt-cpus", "step=999"}, {"--max-step-rate-factor", "0.5"}}) {
    auto setup = fake_setup("event");
    setup.server_args = bad;
    st::Session ses(setup, "step_bad", 5.0);
    EXPECT_EQ(ses.server.wait(30), 2) << bad[0] << " " << bad[1] << "\n" << ses.server.log();
  }
}
