// process_stats against the kernel's other reports: resident memory grows by what the test
// touches, CPU time agrees with the process clock and reads a child whose command name holds ") (",
// a process that does not exist reads -1, and the memory this process can still get is bounded
// by an address-space limit set in a child.
#include "common/process_stats.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace neurosim::common {
namespace {

// CPU time of this process by the kernel's process clock (all threads), unit s.
double clock_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// Burns at least `seconds` of this process's CPU time (not wall time: load does not change it).
double burn_cpu(double seconds) {
  volatile double x = 1.0;
  const double start = clock_seconds();
  while (clock_seconds() - start < seconds)
    for (int i = 0; i < 100000; ++i) x = x * 1.0000001 + 1e-9;
  return x;
}

TEST(common_process_stats, ResidentMemoryGrowsByWhatIsTouched) {
  const long before = resident_kib();
  ASSERT_GT(before, 0);
  constexpr std::size_t kBytes = 64u << 20;  // 64 MiB
  std::vector<char> block(kBytes);
  for (std::size_t i = 0; i < kBytes; i += 4096) block[i] = static_cast<char>(i);
  const long after = resident_kib(getpid());  // the same process by its pid
  EXPECT_GE(after - before, 56L * 1024) << before << " -> " << after << " KiB";
  EXPECT_EQ(block[4096], static_cast<char>(4096));
}

TEST(common_process_stats, CpuTimeAgreesWithTheProcessClock) {
  burn_cpu(0.2);
  const double a = clock_seconds();
  const double ours = cpu_seconds();
  const double b = clock_seconds();
  // /proc's clock ticks (10 ms) against the process clock's nanoseconds.
  const double tick = 1.0 / static_cast<double>(sysconf(_SC_CLK_TCK));
  EXPECT_GE(ours, a - 2 * tick);
  EXPECT_LE(ours, b + 2 * tick);
  EXPECT_GE(ours, 0.2 - 2 * tick);
}

TEST(common_process_stats, ReadsAChildWhoseNameHoldsParenthesesAndSpaces) {
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    prctl(PR_SET_NAME, "a) b (c) 1 2 3", 0, 0, 0);
    burn_cpu(0.1);
    const char c = 'x';
    if (write(ready[1], &c, 1) != 1) _exit(2);
    pause();
    _exit(0);
  }
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1);
  std::ifstream comm("/proc/" + std::to_string(child) + "/comm");
  std::string name;
  std::getline(comm, name);
  EXPECT_EQ(name, "a) b (c) 1 2 3");
  const double cpu = cpu_seconds(child);
  const long rss = resident_kib(child);
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  close(ready[0]);
  close(ready[1]);
  const double tick = 1.0 / static_cast<double>(sysconf(_SC_CLK_TCK));
  EXPECT_GE(cpu, 0.1 - 2 * tick);
  EXPECT_LT(cpu, 60.0);
  EXPECT_GT(rss, 0);
  // Gone now: unknown.
  EXPECT_EQ(cpu_seconds(child), -1.0);
  EXPECT_EQ(resident_kib(child), -1);
}

TEST(common_process_stats, ProcessesThatDoNotExistReadMinusOne) {
  long pid_max = 0;
  std::ifstream("/proc/sys/kernel/pid_max") >> pid_max;
  ASSERT_GT(pid_max, 0);
  const auto none = static_cast<pid_t>(pid_max + 1);  // above the largest pid the kernel gives
  EXPECT_EQ(cpu_seconds(none), -1.0);
  EXPECT_EQ(resident_kib(none), -1);
}

TEST(common_process_stats, MemoryAvailableIsBoundedByTheAddressSpaceLimit) {
  const char* source = nullptr;
  const double free_bytes = memory_available_bytes(&source);
  ASSERT_NE(source, nullptr);
  EXPECT_GT(free_bytes, 0.0);
  EXPECT_TRUE(std::string(source) == "MemAvailable" || std::string(source) == "RLIMIT_AS" ||
              std::string(source) == "cgroup memory.max")
      << source;
  // In a child: RLIMIT_AS = its virtual size + 100 MiB, far below any machine's MemAvailable and
  // cgroup limit here; the answer is that room, named RLIMIT_AS. Exit status 0 = as expected.
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    long vm_kib = -1;
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
      if (line.rfind("VmSize:", 0) == 0) vm_kib = std::stol(line.substr(7));
    if (vm_kib <= 0) _exit(2);
    const double room = 100.0 * 1024 * 1024;
    rlimit as{};
    as.rlim_cur = as.rlim_max = static_cast<rlim_t>(1024.0 * static_cast<double>(vm_kib) + room);
    if (setrlimit(RLIMIT_AS, &as) != 0) _exit(3);
    const char* from = nullptr;
    const double got = memory_available_bytes(&from);
    if (from == nullptr || std::strcmp(from, "RLIMIT_AS") != 0) _exit(4);
    if (!(std::abs(got - room) < 8.0 * 1024 * 1024)) _exit(5);  // VmSize moves by a few pages
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "2: no VmSize, 3: setrlimit failed, 4: another bound "
                                       "named, 5: not the room left under the limit";
}

}  // namespace
}  // namespace neurosim::common
