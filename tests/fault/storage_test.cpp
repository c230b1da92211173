// A full disk and a read-only output folder, for the files a session writes: recordings
// (idl/wire/recording_io, neurosim-haptic --record) and the compliance cache
// (server/interaction/boundary_cache). Each gets a clear error naming the file, the session goes
// on without it, and nothing half-written is left where it could be read back later.
#include "idl/wire/recording_io.hpp"
#include "server/interaction/boundary_cache.hpp"
#include "fault/scratch_mount.hpp"
#include "server/service/service_test_util.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <random>

namespace fs = std::filesystem;
namespace wire = neurosim::wire;
namespace ni = neurosim::interaction;
namespace recording = neurosim::recording;
using neurosim::service::testing::ChildProcess;
using neurosim::testing::entries;

namespace {

class Storage : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { why_ = neurosim::testing::enter_private_mounts(); }
  void SetUp() override {
    if (!why_.empty()) GTEST_SKIP() << "storage faults need a private mount namespace: " << why_;
    dir_ = neurosim::testing::temp_dir("fault_storage");
  }
  void TearDown() override {
    for (const auto& m : mounts_) neurosim::testing::unmount(m);
    if (!dir_.empty()) fs::remove_all(dir_);
  }
  // A tmpfs of `bytes` under the test's folder; full: filled to the last byte.
  fs::path small_disk(const std::string& name, std::size_t bytes, bool full) {
    const fs::path m = dir_ / name;
    const std::string err = neurosim::testing::mount_small_tmpfs(m, bytes);
    if (!err.empty()) throw std::runtime_error(err);
    mounts_.push_back(m);
    if (full) neurosim::testing::fill_up(m);
    return m;
  }
  fs::path read_only_disk(const std::string& name) {
    const fs::path m = small_disk(name, 1 << 20, false);
    const std::string err = neurosim::testing::remount_read_only(m);
    if (!err.empty()) throw std::runtime_error(err);
    return m;
  }
  static std::string why_;
  fs::path dir_;
  std::vector<fs::path> mounts_;
};
std::string Storage::why_;

recording::Header header() {
  recording::Header h;
  h.set_station_id("fault");
  return h;
}

recording::Sample sample(int i) {
  recording::Sample s;
  s.set_time_s(1e-3 * i);
  s.mutable_position_m()->set_x(1e-4 * i);
  s.mutable_orientation()->set_w(1);
  return s;
}

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

ni::BoundaryOperator random_operator(int m3, int s3) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  ni::BoundaryOperator op;
  op.l_bb = Eigen::MatrixXd::NullaryExpr(m3, m3, [&] { return u(rng); });
  op.l_sb = Eigen::MatrixXd::NullaryExpr(s3, m3, [&] { return u(rng); });
  op.k_add = Eigen::MatrixXd::NullaryExpr(m3, m3, [&] { return u(rng); });
  op.g = Eigen::MatrixXd::NullaryExpr(m3, m3, [&] { return u(rng); });
  return op;
}

}  // namespace

TEST_F(Storage, RecordingOnAFullDiskFailsNamingTheFileAndLeavesNothing) {
  const fs::path disk = small_disk("full", 64 << 10, false);
  const fs::path file = disk / "session.rec";
  std::string error;
  std::size_t written = 0;
  try {
    wire::RecordingWriter w(file, header());
    for (int i = 0; i < 5000; ++i, ++written) w.write(sample(i));  // ~650 kB > 64 kB
    w.close();
  } catch (const std::runtime_error& e) {
    error = e.what();
  }
  EXPECT_NE(error.find(file.string()), std::string::npos) << error;
  EXPECT_NE(error.find("No space left"), std::string::npos) << error;
  EXPECT_GT(written, 10u) << "the disk was full before the first samples: not the case tested";
  EXPECT_TRUE(entries(disk).empty()) << "left behind: " << entries(disk).size() << " files";
}

TEST_F(Storage, RecordingInAReadOnlyFolderFailsAtOnceNamingTheFile) {
  const fs::path disk = read_only_disk("ro");
  const fs::path file = disk / "session.rec";
  const std::string error =
      neurosim::testing::message_of([&] { wire::RecordingWriter w(file, header()); });
  EXPECT_NE(error.find(file.string()), std::string::npos) << error;
  EXPECT_NE(error.find("Read-only"), std::string::npos) << error;
  EXPECT_TRUE(entries(disk).empty());
}

TEST_F(Storage, ACutRecordingIsNeverReadBackUnderItsName) {
  // A writer that dies mid-session (no close) leaves only the .partial; close() publishes the
  // whole recording under its name.
  const fs::path file = dir_ / "cut.rec";
  const pid_t pid = ::fork();
  if (pid == 0) {
    wire::RecordingWriter w(file, header());
    for (int i = 0; i < 1000; ++i) w.write(sample(i));
    ::_exit(0);  // no destructor, no close: as a crash
  }
  int st = 0;
  ASSERT_EQ(::waitpid(pid, &st, 0), pid);
  EXPECT_FALSE(fs::exists(file));
  EXPECT_TRUE(fs::exists(file.string() + ".partial"));
  EXPECT_NE(neurosim::testing::message_of([&] { wire::RecordingReader r(file); })
                .find("cannot open"),
            std::string::npos);

  const fs::path whole = dir_ / "whole.rec";
  {
    wire::RecordingWriter w(whole, header());
    for (int i = 0; i < 1000; ++i) w.write(sample(i));
    EXPECT_FALSE(fs::exists(whole)) << "visible before close";
    w.close();
  }
  EXPECT_FALSE(fs::exists(whole.string() + ".partial"));
  wire::RecordingReader r(whole);
  recording::Sample s;
  int n = 0;
  while (r.next(s)) ++n;
  EXPECT_EQ(n, 1000);
}

TEST_F(Storage, ComplianceCacheOnAFullOrReadOnlyDiskIsSkippedAndLeavesNothing) {
  const auto op = random_operator(30, 12);
  for (const fs::path& disk : {small_disk("full", 16 << 10, true), read_only_disk("ro")}) {
    const fs::path file = disk / "body.cache";
    const auto before = entries(disk);
    ::testing::internal::CaptureStderr();
    ni::save_boundary_operator(file.string(), 42, op);
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find(file.string()), std::string::npos) << err;
    EXPECT_NE(err.find("continuing without it"), std::string::npos) << err;
    EXPECT_EQ(entries(disk), before) << "a temporary or partial cache file was left in " << disk;
    ni::BoundaryOperator back;
    EXPECT_FALSE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));
  }
}

TEST_F(Storage, DamagedComplianceCacheIsDetectedByItsChecksum) {
  const auto op = random_operator(30, 12);
  const fs::path file = dir_ / "body.cache";
  ni::save_boundary_operator(file.string(), 42, op);
  ni::BoundaryOperator back;
  ASSERT_TRUE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));
  EXPECT_EQ(back.g, op.g);
  EXPECT_EQ(back.l_sb, op.l_sb);
  EXPECT_EQ(entries(dir_).size(), 1u) << "a temporary was left beside the cache file";

  const auto bytes = fs::file_size(file);
  auto patch = [&](std::uintmax_t offset, char flip) {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(offset));
    char c = 0;
    f.get(c);
    f.seekp(static_cast<std::streamoff>(offset));
    f.put(static_cast<char>(c ^ flip));
  };
  // One bit of one mantissa in the middle: still a finite number, only the checksum can tell.
  patch(bytes / 2, 0x01);
  ::testing::internal::CaptureStderr();
  EXPECT_FALSE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));
  EXPECT_NE(::testing::internal::GetCapturedStderr().find("checksum"), std::string::npos);
  patch(bytes / 2, 0x01);  // repaired
  ASSERT_TRUE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));

  fs::resize_file(file, bytes - 8);  // cut short
  ::testing::internal::CaptureStderr();
  EXPECT_FALSE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));
  ::testing::internal::GetCapturedStderr();
  fs::resize_file(file, bytes + 8);  // trailing bytes
  ::testing::internal::CaptureStderr();
  EXPECT_FALSE(ni::load_boundary_operator(file.string(), 42, 30, 12, back));
  ::testing::internal::GetCapturedStderr();
}

// The station's own binary: the recording fails mid-session on a full disk (and at the start in
// a read-only folder); neurosim-haptic says so at once, runs its whole session, prints its
// summary, leaves no file and exits 1.
TEST_F(Storage, HapticStationGoesOnWithoutItsRecording) {
  const fs::path haptic = neurosim::testing::bin_dir() / "neurosim-haptic";
  ASSERT_TRUE(fs::exists(haptic)) << haptic;
  struct Case {
    fs::path disk;
    const char* what;
  };
  for (const Case& c : {Case{small_disk("full", 64 << 10, false), "No space left"},
                        Case{read_only_disk("ro"), "Read-only"}}) {
    const fs::path file = c.disk / "session.rec";
    const fs::path log = dir_ / "haptic.log";
    ChildProcess station(haptic,
                         {"--station", "fault", "--device", "script:press", "--duration", "10",
                          "--no-server", "--no-rt", "--record", file.string()},
                         log);
    // Said at once: while the session still runs (a 1 kHz recording fills 64 kB in < 1 s; the
    // 10 s session leaves room for a loaded machine's slower ticks).
    const auto t0 = neurosim::common::Clock::now();
    bool said = false;
    while (!said && station.alive() && neurosim::common::seconds_since(t0) < 9) {
      said = station.log().find("goes on without the recording") != std::string::npos;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    EXPECT_TRUE(said) << "not said while the session ran: " << station.log();
    EXPECT_EQ(station.wait(20), 1) << station.log();
    const std::string out = station.log();
    EXPECT_NE(out.find(file.string()), std::string::npos) << out;
    EXPECT_NE(out.find(c.what), std::string::npos) << out;
    EXPECT_NE(out.find("ticks"), std::string::npos) << "no summary: " << out;
    const auto left = entries(c.disk);
    EXPECT_FALSE(contains(left, "session.rec")) << c.disk;
    EXPECT_FALSE(contains(left, "session.rec.partial")) << c.disk;
  }
}
