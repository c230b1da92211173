// Helpers for the DDS Security tests: a fresh test PKI from deploy/secure/make-test-pki, this
// process joining a domain with one identity (deploy/cyclonedds/secure.xml), child processes with
// their own configuration and identity, a ToolState writer in a chosen partition, and the skip
// (exit code 77) when openssl or Cyclone's security plugins are missing.
//
// Cyclone DDS reads CYCLONEDDS_URI (and expands ${NEUROSIM_SECURE_DIR}, ${NEUROSIM_IDENTITY}) when
// it creates a domain, i.e. at the first participant of a domain id in a process: join_as() sets
// them for the domains this process creates afterwards. ctest runs every test in its own process.
#pragma once

#include "tests/server/service/service_test_util.hpp"

#include <dds/dds.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace neurosim::security::testing {

namespace fs = std::filesystem;
namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace wire = neurosim::wire;

inline std::string loopback_uri() {
  return "file://" + (nt::source_dir() / "deploy/cyclonedds/loopback.xml").string();
}
inline std::string secure_uri() {
  return "file://" + (nt::source_dir() / "deploy/cyclonedds/secure.xml").string();
}

// What is missing for secured DDS on this machine ("" when nothing is): openssl (to make the
// PKI) or the Cyclone DDS security plugins (Debian: libddsc0debian, in its own folder).
inline std::string missing_prerequisite() {
  if (std::system("command -v openssl >/dev/null 2>&1") != 0) return "openssl not found (apt-get install openssl)";
  const fs::path plugins = NEUROSIM_DDS_SECURITY_PLUGIN_DIR;
  for (const char* lib : {"libdds_security_auth.so", "libdds_security_ac.so", "libdds_security_crypto.so"})
    if (!fs::exists(plugins / lib))
      return "Cyclone DDS security plugin " + (plugins / lib).string() + " not found (apt-get install libddsc0debian)";
  return "";
}

// Registered once per test program: before the first test runs (not while ctest lists them),
// a machine without openssl or the plugins ends the program with 77, which ctest reports as
// skipped (SKIP_RETURN_CODE, tests/security/CMakeLists.txt).
class SkipWithoutPrerequisites : public ::testing::Environment {
 public:
  void SetUp() override {
    const std::string missing = missing_prerequisite();
    if (missing.empty()) return;
    std::fprintf(stderr, "SKIPPED: DDS Security tests need %s\n", missing.c_str());
    std::fflush(stderr);
    std::_Exit(77);
  }
};
inline const auto* const kSkipEnvironment = ::testing::AddGlobalTestEnvironment(new SkipWithoutPrerequisites);

// A fresh test PKI (make-test-pki) in the build tree: CA, governance, identities "server",
// "station-<id>" for each station id, "viewer" and "observer". Throws (naming the command and its
// output) if the script fails.
inline fs::path make_pki(const std::string& tag, const std::vector<std::string>& stations) {
  const fs::path dir = fs::path(NEUROSIM_SECURITY_WORK_DIR) / (tag + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir.parent_path());
  std::string ids;
  for (const auto& s : stations) ids += (ids.empty() ? "" : " ") + s;
  const std::string cmd = "'" + (nt::source_dir() / "deploy/secure/make-test-pki").string() + "' --out '" +
                          dir.string() + "' --stations '" + ids + "' >'" + dir.string() + ".log' 2>&1";
  if (std::system(cmd.c_str()) != 0)
    throw std::runtime_error("make-test-pki failed: " + cmd + "\n" + nt::slurp(dir.string() + ".log"));
  return dir;
}

// The DDS domains this process creates from now on use secure.xml with this identity.
inline void join_as(const fs::path& pki, const std::string& identity) {
  ::setenv("CYCLONEDDS_URI", secure_uri().c_str(), 1);
  ::setenv("NEUROSIM_SECURE_DIR", pki.c_str(), 1);
  ::setenv("NEUROSIM_IDENTITY", identity.c_str(), 1);
}

// The DDS environment of a child: a configuration URI and, for secure.xml, the PKI and identity.
struct ChildEnv {
  std::string uri = loopback_uri();
  fs::path pki;
  std::string identity;
  static ChildEnv secured(const fs::path& pki, const std::string& identity) { return {secure_uri(), pki, identity}; }
  static ChildEnv plain() { return {}; }
};

// argv for ChildProcess that runs exe under env(1) with this DDS environment (this process's own
// environment stays as it is).
inline std::vector<std::string> with_env(const ChildEnv& e, const fs::path& exe, const std::vector<std::string>& args) {
  std::vector<std::string> a{"CYCLONEDDS_URI=" + e.uri};
  if (!e.identity.empty()) {
    a.push_back("NEUROSIM_SECURE_DIR=" + e.pki.string());
    a.push_back("NEUROSIM_IDENTITY=" + e.identity);
  }
  a.push_back(exe.string());
  a.insert(a.end(), args.begin(), args.end());
  return a;
}
inline const fs::path kEnv = "/usr/bin/env";

// The server code (server/service) with the test-only analytic physics on
// tests/server/service/data/fake_box.scene: a probe pressed into the +x face of a 0.1 m box.
inline fs::path fake_server_exe() { return nt::bin_dir() / "service_test_fake_server"; }
inline std::vector<std::string> fake_server_args(int domain, double duration_s) {
  return {"--scene", (nt::source_dir() / "tests/server/service/data/fake_box.scene").string(), "--domain",
          std::to_string(domain), "--duration", std::to_string(duration_s)};
}
inline constexpr const char* kFakeSceneName = "service_fake_box";
// A tool tip 2 mm inside the box's +x face (tip radius 3 mm): in contact.
inline std::array<double, 3> press_position(double dy = 0) { return {0.1 + 0.003 - 0.002, 0.05 + dy, 0.05}; }

inline int other_domain(int domain) {
  int d = st::private_domain();
  while (d == domain) d = st::private_domain();
  return d;
}

// A ToolState writer in one chosen partition (its publisher's), made with the C API so a test
// can claim any partition, including one its permissions refuse. The writer's QoS is the topic's.
class PartitionToolWriter {
 public:
  PartitionToolWriter(const wire::Participant& pp, const wire::Topic<neurosim_ToolState>& topic,
                      const std::string& partition) {
    dds_qos_t* pq = dds_create_qos();
    const char* parts[] = {partition.c_str()};
    dds_qset_partition(pq, 1, parts);
    const dds_entity_t pub = dds_create_publisher(pp.handle(), pq, nullptr);
    dds_delete_qos(pq);
    if (pub < 0) {
      rc_ = pub;
      return;
    }
    pub_ = wire::Entity(pub);
    const wire::Qos q = wire::topic_qos(wire::Profile::ToolState);
    rc_ = dds_create_writer(pub, topic.handle(), q.get(), nullptr);
    if (rc_ > 0) writer_ = rc_;
  }
  // The writer's handle (> 0), or the DDS return code that refused it (< 0).
  dds_return_t created() const { return rc_; }
  dds_entity_t handle() const { return writer_; }
  void write(const neurosim_ToolState& s) const {
    const dds_return_t rc = dds_write(writer_, &s);
    if (rc < 0) throw std::runtime_error(std::string("write ToolState: ") + dds_strretcode(rc));
  }

 private:
  wire::Entity pub_;  // deleting the publisher deletes the writer
  dds_return_t rc_{0};
  dds_entity_t writer_{0};
};

// Writes ToolState samples (station_id, position) at 1 kHz for `seconds` from this thread.
inline void write_for(const PartitionToolWriter& w, const std::string& station_id, const std::array<double, 3>& p,
                      double seconds, std::uint64_t& seq) {
  wire::Sample<neurosim_ToolState> s;
  const auto t0 = st::Clock::now();
  std::int64_t next = neurosim::common::monotonic_ns();
  while (st::seconds_since(t0) < seconds) {
    st::fill_tool(*s, station_id.c_str(), ++seq, p.data(), dds_time());
    w.write(*s);
    next += 1000000;
    neurosim::common::sleep_until_ns(next);
  }
}

}  // namespace neurosim::security::testing
