// TextReader on hostile input: a named pipe, a device or a directory is refused before reading, a
// file above the byte limit by its size, and a count that cannot fit in the rest of the file is
// refused at its line.
#include "server/mesh/text_reader.hpp"

#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <fcntl.h>
#include <unistd.h>
#include <csignal>
#include <fstream>
#include <thread>

namespace neurosim::mesh {
namespace {

namespace fs = std::filesystem;
using neurosim::testing::message_of;

// A device is refused before anything is read (/dev/zero never ends; a reader that read it
// reached 536 MB before its limit).
TEST(TextReader, DeviceIsRefusedBeforeReading) {
  const std::string e = message_of([] { TextReader("/dev/zero", '#', 1 << 20); });
  EXPECT_EQ(e, "/dev/zero: mesh file: is a character device, not a regular file") << e;
}

// A mesh path that is a named pipe no one writes to: opening it for reading would block for
// ever; it is refused at once, naming it.
TEST(TextReader, NamedPipeIsRefusedWithoutBlocking) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_fifo");
  const std::string fifo = (dir / "pipe.mesh").string();
  const std::string e = neurosim::testing::message_of_reading_a_fifo(
      fifo, [](const std::string& p) { TextReader(p, '#', 1 << 20); });
  EXPECT_EQ(e, fifo + ": mesh file: is a named pipe, not a regular file") << e;
  fs::remove_all(dir);
}

// So is a directory.
TEST(TextReader, DirectoryIsRefused) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_dir");
  const std::string e = message_of([&] { TextReader(dir.string(), '#'); });
  EXPECT_EQ(e, dir.string() + ": mesh file: is a directory, not a regular file") << e;
  fs::remove_all(dir);
}

TEST(TextReader, FileAtTheLimitIsRead) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_limit");
  const std::string path = (dir / "a.txt").string();
  std::ofstream(path) << "12 34\n";
  TextReader in(path, '#', 6);
  EXPECT_EQ(in.integer("a"), 12);
  EXPECT_EQ(in.integer("b"), 34);
  EXPECT_EQ(message_of([&] { TextReader(path, '#', 5); }),
            path + ": mesh file: 6 bytes, above the limit of 5 bytes");
  fs::remove_all(dir);
}

TEST(TextReader, CountIsCheckedAgainstTheBytesLeft) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_count");
  const std::string path = (dir / "a.txt").string();
  std::ofstream(path) << "header\n3\n1 2\n3 4\n5 6";  // three entries of 2 numbers, 11 bytes left
  TextReader in(path, '#');
  in.token("header");
  in.integer("count");
  in.end_line();
  in.check_count(5, 2, "pairs");  // 5 x 2 <= 11: not impossible (the entries say what is wrong)
  EXPECT_EQ(
      message_of([&] { in.check_count(6, 2, "pairs"); }),
      path + ":2: 6 pairs cannot fit in the 11 bytes left in the file (each takes at least 2)");
  EXPECT_NE(
      message_of([&] { in.check_count(1000000000000LL, 1, "x"); }).find(":2: 1000000000000 x"),
      std::string::npos);
  EXPECT_NE(message_of([&] { in.check_count(-1, 1, "x"); }).find(":2: bad number of x: -1"),
            std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::mesh
