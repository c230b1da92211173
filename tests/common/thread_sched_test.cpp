// common::ThreadPlan parsing (--rt-priority / --rt-cpus) and apply_to_this_thread: the thread is
// named, gets what is permitted, and the line says what it got.
#include "common/thread_sched.hpp"

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <functional>
#include <string>
#include <thread>

namespace nc = neurosim::common;

namespace {

nc::ThreadPlan plan() {
  nc::ThreadPlan p;
  p.threads = {{"step", "ns-step", 50, {}}, {"dds", "ns-dds", 45, {}}, {"field", "ns-field", 0, {}}};
  return p;
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(thread_sched, PrioritiesParsedIntoThePlan) {
  auto p = plan();
  EXPECT_EQ(p.priorities_text(), "step=50,dds=45,field=0");
  nc::apply_priorities(p, "step=60,field=5", "--rt-priority");
  EXPECT_EQ(p.at("step").priority, 60);
  EXPECT_EQ(p.at("dds").priority, 45);  // untouched
  EXPECT_EQ(p.at("field").priority, 5);
  nc::apply_priorities(p, "", "--rt-priority");  // nothing given: nothing changes
  EXPECT_EQ(p.priorities_text(), "step=60,dds=45,field=5");
}

TEST(thread_sched, BadPrioritiesNameTheOptionAndEntry) {
  auto p = plan();
  const std::string unknown = error_of([&] { nc::apply_priorities(p, "stepper=3", "--rt-priority"); });
  EXPECT_NE(unknown.find("--rt-priority"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("stepper"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("step, dds, field"), std::string::npos) << unknown;
  EXPECT_NE(error_of([&] { nc::apply_priorities(p, "step=100", "--rt-priority"); }).find("step=100"),
            std::string::npos);
  EXPECT_NE(error_of([&] { nc::apply_priorities(p, "step=-1", "--rt-priority"); }), "");
  EXPECT_NE(error_of([&] { nc::apply_priorities(p, "step=5x", "--rt-priority"); }).find("not an integer"),
            std::string::npos);
  EXPECT_NE(error_of([&] { nc::apply_priorities(p, "step", "--rt-priority"); }).find("ROLE=VALUE"),
            std::string::npos);
  EXPECT_EQ(p.priorities_text(), "step=50,dds=45,field=0");  // nothing applied by a bad spec
}

TEST(thread_sched, CpuSetsParsedAndCheckedAgainstTheMachine) {
  auto p = plan();
  nc::apply_cpus(p, "step=0,field=0-0+0", "--rt-cpus");
  EXPECT_EQ(p.at("step").cpus, std::vector<int>{0});
  EXPECT_EQ(p.at("field").cpus, std::vector<int>{0});  // duplicates merged
  EXPECT_TRUE(p.at("dds").cpus.empty());
  const long n = sysconf(_SC_NPROCESSORS_CONF);
  const std::string too_high = error_of([&] { nc::apply_cpus(p, "dds=" + std::to_string(n), "--rt-cpus"); });
  EXPECT_NE(too_high.find("--rt-cpus"), std::string::npos) << too_high;
  EXPECT_NE(error_of([&] { nc::apply_cpus(p, "dds=1-0", "--rt-cpus"); }), "");
  EXPECT_EQ(nc::cpus_text({0, 1, 2, 5}), "0-2,5");
  EXPECT_EQ(nc::cpus_text({}), "any");
}

TEST(thread_sched, AppliedToTheCallingThreadAndSaid) {
  std::string line, name;
  int policy = -1;
  cpu_set_t set;
  CPU_ZERO(&set);
  std::thread t([&] {
    line = nc::apply_to_this_thread({"field", "nt-test-thread", 0, {0}});
    char buf[32] = {};
    pthread_getname_np(pthread_self(), buf, sizeof buf);
    name = buf;
    sched_param sp{};
    pthread_getschedparam(pthread_self(), &policy, &sp);
    pthread_getaffinity_np(pthread_self(), sizeof set, &set);
  });
  t.join();
  EXPECT_EQ(name, "nt-test-thread");
  EXPECT_EQ(policy, SCHED_OTHER);
  EXPECT_NE(line.find("thread nt-test-thread (field): SCHED_OTHER"), std::string::npos) << line;
  if (line.find("refused") == std::string::npos) {
    EXPECT_EQ(CPU_COUNT(&set), 1) << line;
    EXPECT_TRUE(CPU_ISSET(0, &set)) << line;
  }
  // A real-time request: granted (the line says SCHED_FIFO and the thread has it) or refused
  // (the line says why and the thread runs normally), never silently neither.
  std::thread f([&] {
    line = nc::apply_to_this_thread({"step", "nt-fifo", 10, {}});
    sched_param sp{};
    pthread_getschedparam(pthread_self(), &policy, &sp);
  });
  f.join();
  if (policy == SCHED_FIFO)
    EXPECT_NE(line.find("SCHED_FIFO priority 10"), std::string::npos) << line;
  else
    EXPECT_NE(line.find("SCHED_FIFO 10 refused"), std::string::npos) << line;
}
