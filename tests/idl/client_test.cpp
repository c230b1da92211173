// wire::ClientSession, the client set-up neurosim-haptic, neurosim-viewer and neurosim-web share:
// topics under the run's prefix, and the server seen alive through its SimStatus writer's
// liveliness (a writer of the test's own, in process, on loopback).
#include "idl/wire/client.hpp"

#include "tests/idl/wire_test_util.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <optional>
#include <thread>

namespace {

namespace ns = neurosim::wire;
using neurosim::wire::testing::unique_topic;

// Polls `pred` every 20 ms for at most `seconds`.
template <class Pred>
bool eventually(double seconds, Pred pred) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return pred();
}

TEST(wire_client, TopicsCarryTheRunsPrefix) {
  const std::string prefix = unique_topic("run") + "_";
  ns::ClientSession session(ns::ClientOptions{-1, prefix});
  EXPECT_EQ(session.topic<neurosim_Deformation>().name(), ns::topic_name<neurosim_Deformation>(prefix));
  EXPECT_EQ(session.topic<neurosim_ContactModel>().name().rfind(prefix, 0), 0u);
}

TEST(wire_client, TheServerIsAliveWhileItsStatusWriterIs) {
  const std::string prefix = unique_topic("run") + "_";
  ns::ClientSession session(ns::ClientOptions{-1, prefix});
  EXPECT_FALSE(session.server_alive()) << "no server yet";
  {
    ns::Participant server_pp;
    ns::Topic<neurosim_SimStatus> topic(server_pp, ns::topic_name<neurosim_SimStatus>(prefix));
    ns::Writer<neurosim_SimStatus> writer(server_pp, topic);
    ns::Sample<neurosim_SimStatus> st;
    ns::set_string(st->server_id, "test-server", "server_id");
    writer.write(*st);
    EXPECT_TRUE(eventually(10, [&] { return session.server_alive(); }));
    // The status wakes the session's waitset with the status token.
    bool status_seen = false;
    EXPECT_TRUE(eventually(10, [&] {
      const auto r = session.waitset().wait(DDS_MSECS(50));
      status_seen = status_seen || r.has(ns::ClientSession::kStatusData);
      for (const auto& rx : session.status().take()) (void)rx;
      return status_seen;
    }));
  }
  // The server's participant is gone: its writer is not alive any more.
  EXPECT_TRUE(eventually(10, [&] { return !session.server_alive(); }));
}

}  // namespace
