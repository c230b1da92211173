// service_test_station: a scripted station in its own process, for "a station vanishes
// mid-contact": writes ToolState for STATION at POSITION (x y z, m) at 1 kHz on DOMAIN until
// killed, for at most 30 s (bounded if orphaned).
#include "idl/wire/dds.hpp"

#include <time.h>

#include <cstdio>
#include <cstdlib>
#include <string>

int main(int argc, char** argv) {
  namespace wire = neurosim::wire;
  if (argc != 6) {
    std::fprintf(stderr, "usage: %s DOMAIN STATION X Y Z\n", argv[0]);
    return 2;
  }
  try {
    wire::ParticipantOptions o;
    o.domain = static_cast<dds_domainid_t>(std::atoi(argv[1]));
    wire::Participant pp(o);
    wire::Topic<neurosim_ToolState> t(pp);
    wire::Writer<neurosim_ToolState> w(pp, t);
    wire::Sample<neurosim_ToolState> s;
    wire::set_string(s->station_id, argv[2], "station_id");
    wire::set_string(s->tool_id, "probe", "tool_id");
    for (int i = 0; i < 3; ++i) s->position_m[i] = std::atof(argv[3 + i]);
    s->orientation[0] = 1;
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (std::uint64_t seq = 1; seq <= 30000; ++seq) {
      s->sequence_number = seq;
      s->source_time_ns = dds_time();
      w.write(*s);
      next.tv_nsec += 1000000;
      if (next.tv_nsec >= 1000000000) {
        next.tv_nsec -= 1000000000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "service_test_station: %s\n", e.what());
    return 1;
  }
  return 0;
}
