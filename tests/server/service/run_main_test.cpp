// The neurosim-server command line: usage errors exit 2 before anything is built, an unreadable
// scene exits 1.
#include "server/service/server.hpp"

#include <gtest/gtest.h>

#include <memory>

TEST(service_command_line, BadArgumentsExitTwo) {
  auto never = [](const neurosim::scene::Model&) -> std::unique_ptr<neurosim::interaction::Simulation> {
    ADD_FAILURE() << "no simulation may be built";
    return nullptr;
  };
  const char* a1[] = {"neurosim-server"};
  EXPECT_EQ(neurosim::service::run_main(1, const_cast<char**>(a1), never), 2);
  const char* a2[] = {"neurosim-server", "--scene", "x.scene", "--duration", "-1"};
  EXPECT_EQ(neurosim::service::run_main(5, const_cast<char**>(a2), never), 2);
  const char* a3[] = {"neurosim-server", "--scene", "x.scene", "--bogus"};
  EXPECT_EQ(neurosim::service::run_main(4, const_cast<char**>(a3), never), 2);
  const char* a4[] = {"neurosim-server", "--scene", "/nonexistent/x.scene"};
  EXPECT_EQ(neurosim::service::run_main(3, const_cast<char**>(a4), never), 1);
}
