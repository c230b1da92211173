// write_cache_file: the file appears whole or not at all, and a folder that cannot be written
// is said and survived, not thrown.
#include "common/cache_file.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

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

}  // namespace
}  // namespace neurosim::common
