// Scheduling of one named thread, set in one place: its name (pthread_setname_np, shown by ps,
// top, perf), SCHED_FIFO priority (0: normal SCHED_OTHER) and optional CPU set. A process not
// permitted real-time priority runs anyway: what was granted or refused comes back as one line
// for the log.
//
//   ThreadPlan plan = default_plan;                       // e.g. {{"step", 50}, {"dds", 45}}
//   apply_priorities(plan, "step=60,field=0", "--rt-priority");   // command line
//   apply_cpus(plan, "step=1,dds=0", "--rt-cpus");
//   log(apply_to_this_thread(plan.at("step")));           // on the thread itself, once
#pragma once

#include <string>
#include <vector>

namespace neurosim::common {

struct ThreadSched {
  std::string role;       // key in --rt-priority / --rt-cpus ("step", "dds", ...)
  std::string name;       // thread name, at most 15 characters (the kernel's limit)
  int priority{0};        // SCHED_FIFO priority 1..99; 0: SCHED_OTHER (normal)
  std::vector<int> cpus;  // CPU affinity; empty: any CPU
};

// The threads of one process, by role.
struct ThreadPlan {
  std::vector<ThreadSched> threads;
  // The entry for role; throws std::invalid_argument naming the role if there is none.
  ThreadSched& at(const std::string& role);
  const ThreadSched& at(const std::string& role) const;
  // "step=50,dds=45,field=0" (the --rt-priority form of the current plan).
  std::string priorities_text() const;
};

// Applies "role=P,role=P" (P 0..99) to the plan. Throws std::invalid_argument naming `what`
// (e.g. "--rt-priority") and the offending entry for an unknown role, a bad or out-of-range
// priority or a malformed entry. An empty spec changes nothing.
void apply_priorities(ThreadPlan& plan, const std::string& spec, const std::string& what);
// Applies "role=CPUS,..." where CPUS is a list of CPU numbers and ranges joined by '+'
// (e.g. "step=1,dds=0+1", "field=0-1"). CPUs must be below the machine's count. Throws
// std::invalid_argument as above.
void apply_cpus(ThreadPlan& plan, const std::string& spec, const std::string& what);

// Names the calling thread, sets its policy/priority and CPU set as far as permitted, and
// returns one line saying what was granted (name, policy, priority, CPUs) or refused and why.
std::string apply_to_this_thread(const ThreadSched& t);

// "0-1" / "0,2" style text of a CPU list ("any" when empty).
std::string cpus_text(const std::vector<int>& cpus);

}  // namespace neurosim::common
