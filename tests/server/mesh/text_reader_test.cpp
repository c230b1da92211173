// TextReader on hostile input: a stream that never ends stops at the byte limit, and a count
// that cannot fit in the rest of the file is refused at its line.
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

TEST(TextReader, EndlessDeviceStopsAtTheLimit) {
  const std::string e = message_of([] { TextReader("/dev/zero", '#', 1 << 20); });
  EXPECT_EQ(e.rfind("/dev/zero: larger than the limit of 1048576 bytes", 0), 0u) << e;
}

// A FIFO whose writer never stops (what a mesh path pointing at a pipe gives).
TEST(TextReader, EndlessFifoStopsAtTheLimit) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_fifo");
  const std::string fifo = (dir / "endless.mesh").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::signal(SIGPIPE, SIG_IGN);  // the writer learns that the reader left through EPIPE
  std::thread writer([&] {
    const int fd = ::open(fifo.c_str(), O_WRONLY);
    if (fd < 0) return;
    const std::string line = "Vertices 1\n";
    while (::write(fd, line.data(), line.size()) > 0) {
    }
    ::close(fd);
  });
  const std::string e = message_of([&] { TextReader(fifo, '#', 1 << 20); });
  writer.join();
  EXPECT_EQ(e.rfind(fifo + ": larger than the limit of 1048576 bytes", 0), 0u) << e;
  fs::remove_all(dir);
}

TEST(TextReader, FileAtTheLimitIsRead) {
  const fs::path dir = neurosim::testing::temp_dir("text_reader_limit");
  const std::string path = (dir / "a.txt").string();
  std::ofstream(path) << "12 34\n";
  TextReader in(path, '#', 6);
  EXPECT_EQ(in.integer("a"), 12);
  EXPECT_EQ(in.integer("b"), 34);
  EXPECT_NE(message_of([&] { TextReader(path, '#', 5); }).find("larger than the limit of 5"),
            std::string::npos);
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
