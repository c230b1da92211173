// The neurosim-server command line: usage errors exit 2 before anything is built, an unreadable
// scene exits 1; --cache-dir reaches the simulation factory.
#include "server/service/server.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <memory>

TEST(service_command_line, BadArgumentsExitTwo) {
  auto never = [](const neurosim::scene::Model&, const neurosim::service::ServerOptions&)
      -> std::unique_ptr<neurosim::interaction::Simulation> {
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

TEST(service_command_line, CacheDirReachesTheFactory) {
  std::string seen = "(factory not called)";
  auto record = [&](const neurosim::scene::Model&, const neurosim::service::ServerOptions& o)
      -> std::unique_ptr<neurosim::interaction::Simulation> {
    seen = o.cache_dir;
    throw std::runtime_error("stopped by the test after the factory saw its options");
  };
  const std::string scene = (neurosim::testing::source_dir() / "scenes/cube_cylinder.scene").string();
  const char* a[] = {"neurosim-server", "--scene", scene.c_str(), "--cache-dir", "/tmp/neurosim_cache_x"};
  EXPECT_EQ(neurosim::service::run_main(5, const_cast<char**>(a), record), 1);
  EXPECT_EQ(seen, "/tmp/neurosim_cache_x");
}
