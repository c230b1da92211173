// Time helpers: one conversion between timespec and nanoseconds, absolute sleeps on a POSIX
// clock, and elapsed steady_clock time.
#pragma once

#include <time.h>

#include <cerrno>
#include <chrono>
#include <cstdint>

namespace neurosim::common {

inline constexpr std::int64_t kNsPerS = 1000000000LL;

inline std::int64_t to_ns(const timespec& t) {
  return static_cast<std::int64_t>(t.tv_sec) * kNsPerS + static_cast<std::int64_t>(t.tv_nsec);
}

// ns >= 0 (clock readings); tv_nsec is always in [0, 1e9).
inline timespec to_timespec(std::int64_t ns) {
  timespec t{};
  t.tv_sec = static_cast<time_t>(ns / kNsPerS);
  t.tv_nsec = static_cast<long>(ns % kNsPerS);
  return t;
}

// Reading of a POSIX clock, unit ns.
inline std::int64_t clock_ns(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return to_ns(t);
}
inline std::int64_t monotonic_ns() { return clock_ns(CLOCK_MONOTONIC); }
inline std::int64_t realtime_ns() { return clock_ns(CLOCK_REALTIME); }
// CPU time used by the calling thread, unit ms.
inline double thread_cpu_ms() { return 1e-6 * static_cast<double>(clock_ns(CLOCK_THREAD_CPUTIME_ID)); }

// Sleeps until the absolute time deadline_ns of clock (CLOCK_MONOTONIC by default); a signal
// does not cut the sleep short.
inline void sleep_until_ns(std::int64_t deadline_ns, clockid_t clock = CLOCK_MONOTONIC) {
  const timespec ts = to_timespec(deadline_ns);
  while (clock_nanosleep(clock, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Shortest wall time of `reps` runs of f, unit ms (benchmark tables).
template <class F>
double best_ms(int reps, F&& f) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const Clock::time_point t0 = Clock::now();
    f();
    const double ms = ms_since(t0);
    if (ms < best) best = ms;
  }
  return best;
}

}  // namespace neurosim::common
