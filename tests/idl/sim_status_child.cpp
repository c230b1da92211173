// Child of wire_dds.KilledServerProcessSeenWithinOneSecond: publishes SimStatus "child" on the
// topic named by its argument every 100 ms until killed, for at most 20 s (bounded if orphaned).
#include "common/cli.hpp"
#include "idl/wire/dds.hpp"

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

int main(int argc, char** argv) {
  namespace ns = neurosim::wire;
  std::string topic;
  neurosim::cli::Parser cli("wire_test_sim_status_child",
                            "Publishes SimStatus \"child\" every 100 ms for at most 20 s.");
  cli.add_option("topic", topic, "topic name TOPIC")->required();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    ns::Participant pp;
    ns::Topic<neurosim_SimStatus> t(pp, topic);
    ns::Writer<neurosim_SimStatus> w(pp, t);
    ns::Sample<neurosim_SimStatus> s;
    ns::set_string(s->server_id, "child");
    for (int i = 0; i < 200; ++i) {
      s->steps = static_cast<std::uint64_t>(i);
      w.write(*s);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "wire_test_sim_status_child: %s\n", e.what());
    return 1;
  }
  return 0;
}
