// Child of wire_dds.KilledServerProcessSeenWithinOneSecond: publishes SimStatus "child" on the
// topic named by argv[1] every 100 ms until killed, for at most 20 s (bounded if orphaned).
#include "idl/wire/dds.hpp"

#include <chrono>
#include <cstdio>
#include <thread>

int main(int argc, char** argv) {
  namespace ns = neurosim::wire;
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s TOPIC\n", argv[0]);
    return 2;
  }
  try {
    ns::Participant pp;
    ns::Topic<neurosim_SimStatus> t(pp, argv[1]);
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
