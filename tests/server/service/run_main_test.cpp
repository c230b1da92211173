// The neurosim-server command line: usage errors exit 2 before anything is built, an unreadable
// scene exits 1; --cache-dir and the contact switches reach the simulation factory.
#include "server/service/server.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

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

// The contact switches: a bad value or switches that contradict each other are usage errors
// (exit 2, the message naming them) before the scene is read; good ones reach the factory.
TEST(service_command_line, ContactSwitchesAreCheckedBeforeAnythingIsBuilt) {
  auto never = [](const neurosim::scene::Model&, const neurosim::service::ServerOptions&)
      -> std::unique_ptr<neurosim::interaction::Simulation> {
    ADD_FAILURE() << "no simulation may be built";
    return nullptr;
  };
  const auto run = [&](std::vector<const char*> a, std::string* err) {
    a.insert(a.begin(), {"neurosim-server", "--scene", "/nonexistent/x.scene"});
    ::testing::internal::CaptureStderr();
    const int rc = neurosim::service::run_main(static_cast<int>(a.size()), const_cast<char**>(a.data()), never);
    *err = ::testing::internal::GetCapturedStderr();
    return rc;
  };
  std::string err;
  EXPECT_EQ(run({"--contact-smooth-normals", "maybe"}, &err), 2);
  EXPECT_NE(err.find("--contact-smooth-normals"), std::string::npos) << err;
  EXPECT_EQ(run({"--contact-spread", "7"}, &err), 2);
  EXPECT_NE(err.find("--contact-spread"), std::string::npos) << err;
  EXPECT_EQ(run({"--contact-near-fields", "off"}, &err), 2) << "an unknown switch";
  EXPECT_NE(err.find("--contact-near-fields"), std::string::npos) << err;
  EXPECT_EQ(run({"--barycentric-contact", "--contact-spread", "1"}, &err), 2);
  EXPECT_NE(err.find("contradict"), std::string::npos) << err;
  EXPECT_EQ(run({"--barycentric-contact", "--contact-near-field", "on"}, &err), 2);
  EXPECT_NE(err.find("contradict"), std::string::npos) << err;
  EXPECT_EQ(run({"--contact-spread", "0"}, &err), 2);
  EXPECT_NE(err.find("--contact-near-field off"), std::string::npos) << err;
  // Accepted: the missing scene is the error (exit 1), not the switches.
  EXPECT_EQ(run({"--contact-spread", "0", "--contact-near-field", "off"}, &err), 1) << err;
  EXPECT_EQ(run({"--barycentric-contact"}, &err), 1) << err;
}

TEST(service_command_line, ContactSwitchesReachTheFactory) {
  neurosim::service::ContactSwitches seen;
  bool called = false;
  auto record = [&](const neurosim::scene::Model&, const neurosim::service::ServerOptions& o)
      -> std::unique_ptr<neurosim::interaction::Simulation> {
    seen = o.contact;
    called = true;
    throw std::runtime_error("stopped by the test after the factory saw its options");
  };
  const std::string scene = (neurosim::testing::source_dir() / "scenes/cube_cylinder.scene").string();
  const char* a[] = {"neurosim-server", "--scene", scene.c_str(), "--contact-spread", "1.5",
                     "--contact-smooth-normals", "off", "--contact-near-field", "off"};
  EXPECT_EQ(neurosim::service::run_main(9, const_cast<char**>(a), record), 1);
  ASSERT_TRUE(called);
  EXPECT_FALSE(seen.barycentric);
  ASSERT_TRUE(seen.spread.has_value());
  EXPECT_EQ(*seen.spread, 1.5);
  ASSERT_TRUE(seen.smooth_normals.has_value());
  EXPECT_FALSE(*seen.smooth_normals);
  ASSERT_TRUE(seen.near_field.has_value());
  EXPECT_FALSE(*seen.near_field);
}
