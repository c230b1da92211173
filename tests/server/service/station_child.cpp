// service_test_station: a scripted station in its own process, for "a station vanishes
// mid-contact": writes ToolState for STATION at POSITION (x y z, m) at 1 kHz on DOMAIN until
// killed, for at most 30 s (bounded if orphaned).
//   service_test_station DOMAIN STATION X Y Z
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "idl/wire/dds.hpp"

#include <cstdio>
#include <string>

int main(int argc, char** argv) {
  namespace wire = neurosim::wire;
  namespace cli = neurosim::cli;
  int domain = 0;
  std::string station;
  double position[3] = {0, 0, 0};
  cli::Parser p("service_test_station", "Writes ToolState at 1 kHz for at most 30 s.");
  p.add_option("domain", domain, "DDS domain id DOMAIN")->required()->check(cli::in_range(0, 230));
  p.add_option("station", station, "station id STATION")->required();
  p.add_option("x", position[0], "tool tip X, unit m")->required()->check(cli::finite());
  p.add_option("y", position[1], "tool tip Y, unit m")->required()->check(cli::finite());
  p.add_option("z", position[2], "tool tip Z, unit m")->required()->check(cli::finite());
  if (auto rc = p.parse(argc, argv)) return *rc;
  try {
    wire::ParticipantOptions o;
    o.domain = static_cast<dds_domainid_t>(domain);
    wire::Participant pp(o);
    wire::Topic<neurosim_ToolState> t(pp);
    wire::Writer<neurosim_ToolState> w(pp, t, station);  // in the station's partition
    wire::Sample<neurosim_ToolState> s;
    wire::set_string(s->station_id, station, "station_id");
    wire::set_string(s->tool_id, "probe", "tool_id");
    for (int i = 0; i < 3; ++i) s->position_m[i] = position[i];
    s->orientation[0] = 1;
    std::int64_t next = neurosim::common::monotonic_ns();
    for (std::uint64_t seq = 1; seq <= 30000; ++seq) {
      s->sequence_number = seq;
      s->source_time_ns = dds_time();
      w.write(*s);
      next += 1000000;
      neurosim::common::sleep_until_ns(next);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "service_test_station: %s\n", e.what());
    return 1;
  }
  return 0;
}
