#include "common/thread_sched.hpp"

#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace neurosim::common {

namespace {

std::vector<std::pair<std::string, std::string>> split_entries(const std::string& spec,
                                                               const std::string& what) {
  std::vector<std::pair<std::string, std::string>> out;
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
      throw std::invalid_argument(what + ": '" + item + "' is not ROLE=VALUE");
    out.emplace_back(item.substr(0, eq), item.substr(eq + 1));
  }
  return out;
}

int parse_int(const std::string& text, const std::string& what, const std::string& entry) {
  std::size_t used = 0;
  int v = 0;
  try {
    v = std::stoi(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size())
    throw std::invalid_argument(what + ": '" + entry + "': '" + text + "' is not an integer");
  return v;
}

}  // namespace

ThreadSched& ThreadPlan::at(const std::string& role) {
  for (auto& t : threads)
    if (t.role == role) return t;
  std::string known;
  for (const auto& t : threads) known += (known.empty() ? "" : ", ") + t.role;
  throw std::invalid_argument("unknown thread role '" + role + "' (known: " + known + ")");
}

const ThreadSched& ThreadPlan::at(const std::string& role) const {
  return const_cast<ThreadPlan*>(this)->at(role);
}

std::string ThreadPlan::priorities_text() const {
  std::string s;
  for (const auto& t : threads) s += (s.empty() ? "" : ",") + t.role + "=" + std::to_string(t.priority);
  return s;
}

void apply_priorities(ThreadPlan& plan, const std::string& spec, const std::string& what) {
  for (const auto& [role, value] : split_entries(spec, what)) {
    const std::string entry = role + "=" + value;
    ThreadSched* t = nullptr;
    try {
      t = &plan.at(role);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(what + ": " + e.what());
    }
    const int p = parse_int(value, what, entry);
    if (p < 0 || p > 99)
      throw std::invalid_argument(what + ": '" + entry + "': priority must be 0 (normal) .. 99 (SCHED_FIFO)");
    t->priority = p;
  }
}

void apply_cpus(ThreadPlan& plan, const std::string& spec, const std::string& what) {
  const long n_cpu = sysconf(_SC_NPROCESSORS_CONF);
  for (const auto& [role, value] : split_entries(spec, what)) {
    const std::string entry = role + "=" + value;
    ThreadSched* t = nullptr;
    try {
      t = &plan.at(role);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(what + ": " + e.what());
    }
    std::vector<int> cpus;
    std::stringstream ss(value);
    std::string part;
    while (std::getline(ss, part, '+')) {
      const auto dash = part.find('-');
      const int lo = parse_int(part.substr(0, dash), what, entry);
      const int hi = dash == std::string::npos ? lo : parse_int(part.substr(dash + 1), what, entry);
      if (lo < 0 || hi < lo || hi >= n_cpu)
        throw std::invalid_argument(what + ": '" + entry + "': CPUs must be in 0.." +
                                    std::to_string(n_cpu - 1) + " (this machine)");
      for (int c = lo; c <= hi; ++c) cpus.push_back(c);
    }
    std::sort(cpus.begin(), cpus.end());
    cpus.erase(std::unique(cpus.begin(), cpus.end()), cpus.end());
    t->cpus = cpus;
  }
}

std::string cpus_text(const std::vector<int>& cpus) {
  if (cpus.empty()) return "any";
  std::string s;
  for (std::size_t i = 0; i < cpus.size();) {
    std::size_t j = i;
    while (j + 1 < cpus.size() && cpus[j + 1] == cpus[j] + 1) ++j;
    s += (s.empty() ? "" : ",") + std::to_string(cpus[i]);
    if (j > i) s += "-" + std::to_string(cpus[j]);
    i = j + 1;
  }
  return s;
}

std::string apply_to_this_thread(const ThreadSched& t) {
  std::ostringstream os;
  const std::string name = t.name.substr(0, 15);
  os << "thread " << name << " (" << t.role << "): ";
  pthread_setname_np(pthread_self(), name.c_str());
  if (t.priority > 0) {
    sched_param sp{};
    sp.sched_priority = t.priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (rc == 0)
      os << "SCHED_FIFO priority " << t.priority;
    else
      os << "SCHED_OTHER (SCHED_FIFO " << t.priority << " refused: " << std::strerror(rc) << ")";
  } else {
    sched_param sp{};
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
    os << "SCHED_OTHER (normal, as configured)";
  }
  if (t.cpus.empty()) {
    os << ", CPUs any";
  } else {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (int c : t.cpus) CPU_SET(c, &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    if (rc == 0)
      os << ", CPUs " << cpus_text(t.cpus);
    else
      os << ", CPUs any (affinity " << cpus_text(t.cpus) << " refused: " << std::strerror(rc) << ")";
  }
  return os.str();
}

}  // namespace neurosim::common
