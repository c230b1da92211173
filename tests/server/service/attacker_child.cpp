// service_test_attacker: a hostile DDS participant for the fault test, in its own process. On
// DOMAIN, for about 6 s, while a legitimate station LEGIT writes its own ToolState:
//   - its own station "evil-1" (own partition) at 1 kHz at the safe position X Y Z (out of the
//     tissue), every 10th sample spoiled in turn: NaN, 1e30 coordinates, a zero quaternion, a
//     source time 10 s ahead, a sequence number run backwards; then 0.5 s at 20 kHz;
//   - "evil-2" (10 samples, then silent: reclaimed after the idle timeout) and "evil-3" (refused:
//     the participant already holds 2 stations);
//   - LEGIT's id from a writer in LEGIT's partition (bound to another writer: identity) and from
//     a writer in another partition (claim mismatch: identity), pushing 5 mm deeper;
//   - an id flood: FLOOD distinct ids from one writer within ~2 s (identity; memory must stay
//     bounded).
//   service_test_attacker DOMAIN LEGIT X Y Z FLOOD
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "idl/wire/dds.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace {

namespace wire = neurosim::wire;
using neurosim::common::monotonic_ns;
using neurosim::common::sleep_until_ns;

void fill(neurosim_ToolState& s, const std::string& id, std::uint64_t seq, const double p[3]) {
  wire::set_string(s.station_id, id, "station_id");
  wire::set_string(s.tool_id, "probe", "tool_id");
  for (int i = 0; i < 3; ++i) {
    s.position_m[i] = p[i];
    s.velocity_m_per_s[i] = 0;
  }
  s.orientation[0] = 1;
  s.orientation[1] = s.orientation[2] = s.orientation[3] = 0;
  s.sequence_number = seq;
  s.source_time_ns = dds_time();
}

}  // namespace

int main(int argc, char** argv) {
  namespace cli = neurosim::cli;
  int domain = 0;
  std::string legit;
  double safe[3] = {0, 0, 0};
  int flood = 20000;
  cli::Parser p("service_test_attacker", "Sends hostile ToolState samples for about 6 s.");
  p.add_option("domain", domain, "DDS domain id")->required()->check(cli::in_range(0, 230));
  p.add_option("legit", legit, "the legitimate station's id")->required();
  p.add_option("x", safe[0], "safe X, unit m")->required()->check(cli::finite());
  p.add_option("y", safe[1], "safe Y, unit m")->required()->check(cli::finite());
  p.add_option("z", safe[2], "safe Z, unit m")->required()->check(cli::finite());
  p.add_option("flood", flood, "distinct ids of the flood")
      ->required()
      ->check(cli::in_range(0, 1000000));
  if (auto rc = p.parse(argc, argv)) return *rc;
  try {
    wire::ParticipantOptions o;
    o.domain = static_cast<dds_domainid_t>(domain);
    wire::Participant pp(o);
    wire::Topic<neurosim_ToolState> t(pp);
    wire::Writer<neurosim_ToolState> evil1(pp, t, "evil-1");
    wire::Writer<neurosim_ToolState> evil2(pp, t, "evil-2");
    wire::Writer<neurosim_ToolState> evil3(pp, t, "evil-3");
    wire::Writer<neurosim_ToolState> spoof(pp, t, legit);            // the legit station's partition
    wire::Writer<neurosim_ToolState> mismatch(pp, t, "evil-x");      // claims evil-x, writes legit
    wire::Writer<neurosim_ToolState> flooder(pp, t, "flood");        // claims flood, writes flood-N
    for (auto* w : {&evil1, &evil2, &evil3, &spoof, &mismatch, &flooder})
      if (!w->wait_for_readers(1, DDS_SECS(10))) throw std::runtime_error("no server matched");
    wire::Sample<neurosim_ToolState> s;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::uint64_t seq = 0;
    // evil-1 and evil-2 join (two stations: this participant's maximum).
    for (int k = 0; k < 10; ++k) {
      fill(*s, "evil-1", ++seq, safe);
      evil1.write(*s);
      fill(*s, "evil-2", static_cast<std::uint64_t>(k + 1), safe);
      evil2.write(*s);
      sleep_until_ns(monotonic_ns() + 2000000);
    }
    std::int64_t next = monotonic_ns();
    double deeper[3] = {safe[0], safe[1], safe[2]};
    for (int k = 0; k < 2500; ++k) {  // 2.5 s at 1 kHz
      fill(*s, "evil-1", ++seq, safe);
      switch (k % 50) {
        case 10: s->position_m[1] = nan; break;
        case 20: s->position_m[0] = 1e30; break;
        case 30: s->orientation[0] = 0; break;
        case 40: s->source_time_ns += 10000000000LL; break;
        case 45: s->sequence_number = seq - 5; break;
        default: break;
      }
      evil1.write(*s);
      if (k % 10 == 5) {
        fill(*s, "evil-3", static_cast<std::uint64_t>(k + 1), safe);  // participant limit
        evil3.write(*s);
        fill(*s, legit, 1000000 + static_cast<std::uint64_t>(k), deeper);  // bound elsewhere
        s->position_m[0] -= 0.005;
        spoof.write(*s);
        mismatch.write(*s);  // claim mismatch
      }
      next += 1000000;
      sleep_until_ns(next);
    }
    // 0.5 s at 20 kHz.
    next = monotonic_ns();
    for (int k = 0; k < 10000; ++k) {
      fill(*s, "evil-1", ++seq, safe);
      evil1.write(*s);
      next += 50000;
      sleep_until_ns(next);
    }
    // The id flood: distinct ids, ~10000 per second.
    next = monotonic_ns();
    for (int k = 0; k < flood; ++k) {
      fill(*s, "flood-" + std::to_string(k), 1, safe);
      flooder.write(*s);
      if (k % 10 == 9) {
        next += 1000000;
        sleep_until_ns(next);
      }
    }
    std::printf("service_test_attacker: done (%d flood ids)\n", flood);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "service_test_attacker: %s\n", e.what());
    return 1;
  }
  return 0;
}
