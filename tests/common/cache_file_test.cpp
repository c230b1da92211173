// write_cache_file: the file appears whole or not at all, and a folder that cannot be written
// is said and survived, not thrown.
#include "common/cache_file.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <thread>

namespace neurosim::common {
namespace {

std::filesystem::path scratch_dir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("neurosim_cache_file_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  return dir;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(CacheFile, WritesTheWholeFileAndCreatesItsFolder) {
  const auto dir = scratch_dir("whole");
  const auto file = dir / "sub" / "entry.bin";
  ASSERT_TRUE(write_cache_file(file.string(), "Test", "cache", [](std::ostream& out) {
    out << "first line\n" << 42;
  }));
  EXPECT_EQ(slurp(file), "first line\n42");
  // No temporary is left beside it.
  int entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(file.parent_path()))
    ++entries;
  EXPECT_EQ(entries, 1);
  // A second write replaces the file.
  ASSERT_TRUE(write_cache_file(file.string(), "Test", "cache",
                               [](std::ostream& out) { out << "second"; }));
  EXPECT_EQ(slurp(file), "second");
  std::filesystem::remove_all(dir);
}

TEST(CacheFile, AWriterThatFailsLeavesTheOldFileAndNoTemporary) {
  const auto dir = scratch_dir("fail");
  const auto file = dir / "entry.bin";
  ASSERT_TRUE(write_cache_file(file.string(), "Test", "cache",
                               [](std::ostream& out) { out << "kept"; }));
  testing::internal::CaptureStderr();
  EXPECT_FALSE(write_cache_file(file.string(), "Owner", "factor cache", [](std::ostream& out) {
    out << "half";
    out.setstate(std::ios::badbit);  // what a full disk does to the stream
  }));
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("Owner: could not write factor cache " + file.string()), std::string::npos)
      << said;
  EXPECT_NE(said.find("continuing without it"), std::string::npos) << said;
  EXPECT_EQ(slurp(file), "kept");
  int entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++entries;
  EXPECT_EQ(entries, 1);
  std::filesystem::remove_all(dir);
}

TEST(CacheFile, AFolderThatCannotBeMadeIsSaidNotThrown) {
  const auto dir = scratch_dir("blocked");
  std::filesystem::create_directories(dir);
  const auto blocker = dir / "not_a_folder";
  std::ofstream(blocker) << "a file where the folder should be";
  const auto file = blocker / "entry.bin";
  testing::internal::CaptureStderr();
  EXPECT_FALSE(write_cache_file(file.string(), "Owner", "compliance cache",
                                [](std::ostream& out) { out << "x"; }));
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("Owner: could not write compliance cache"), std::string::npos) << said;
  EXPECT_FALSE(std::filesystem::exists(file));
  std::filesystem::remove_all(dir);
}

// Two writers of one key at once (two tests' servers, or two set-ups in one process, starting
// the same scene on a shared cache): each has its own temporary and both rename a whole file.
// Both writers are held inside write() until the other is in it too, so their temporaries
// exist at the same time (with one temporary per process, as before, the second rename found
// no temporary and failed).
TEST(CacheFile, TwoWritersOfOneKeyAtOnceBothStoreAWholeFile) {
  const auto dir = scratch_dir("concurrent");
  const auto file = dir / "entry.bin";
  std::atomic<int> inside{0};
  const std::string a(1 << 16, 'a'), b(1 << 16, 'b');
  bool ok_a = false, ok_b = false;
  auto writer = [&](const std::string& payload, bool& ok) {
    ok = write_cache_file(file.string(), "Test", "cache", [&](std::ostream& out) {
      out << payload.substr(0, payload.size() / 2);
      ++inside;
      const auto t0 = std::chrono::steady_clock::now();
      while (inside.load() < 2 && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(30))
        std::this_thread::yield();
      out << payload.substr(payload.size() / 2);
    });
  };
  std::thread ta(writer, std::cref(a), std::ref(ok_a));
  std::thread tb(writer, std::cref(b), std::ref(ok_b));
  ta.join();
  tb.join();
  EXPECT_EQ(inside.load(), 2);
  EXPECT_TRUE(ok_a);
  EXPECT_TRUE(ok_b);
  const std::string got = slurp(file);
  EXPECT_TRUE(got == a || got == b) << "a mixed or partial file of " << got.size() << " bytes";
  int entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++entries;
  EXPECT_EQ(entries, 1) << "a temporary was left beside the file";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::common
