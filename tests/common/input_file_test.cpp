// read_input_file / require_regular_file: regular files only (a named pipe, a device or a
// directory refused before reading, without blocking), at most the stated size, errors naming
// the file and what it was read as.
#include "common/input_file.hpp"

#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <fstream>

namespace neurosim::common {
namespace {

namespace fs = std::filesystem;
using neurosim::testing::message_of;

TEST(InputFile, RegularFileIsReadWhole) {
  const fs::path dir = neurosim::testing::temp_dir("input_file_regular");
  const std::string path = (dir / "a.txt").string();
  std::ofstream(path) << "12 34\n";
  EXPECT_EQ(read_input_file(path, 6, "test file"), "12 34\n");
  EXPECT_NO_THROW(require_regular_file(path, 6, "test file"));
  EXPECT_EQ(message_of([&] { read_input_file(path, 5, "test file"); }),
            path + ": test file: 6 bytes, above the limit of 5 bytes");
  EXPECT_EQ(message_of([&] { require_regular_file(path, 5, "test file"); }),
            path + ": test file: 6 bytes, above the limit of 5 bytes");
  fs::remove_all(dir);
}

TEST(InputFile, SpecialFilesAreRefusedBeforeReading) {
  EXPECT_EQ(message_of([] { read_input_file("/dev/zero", 1 << 20, "mesh file"); }),
            "/dev/zero: mesh file: is a character device, not a regular file");
  EXPECT_EQ(message_of([] { require_regular_file("/dev/zero", 1 << 20, "image"); }),
            "/dev/zero: image: is a character device, not a regular file");
  const fs::path dir = neurosim::testing::temp_dir("input_file_special");
  EXPECT_EQ(message_of([&] { read_input_file(dir.string(), 1 << 20, "scene file"); }),
            dir.string() + ": scene file: is a directory, not a regular file");
  const std::string fifo = (dir / "pipe").string();
  EXPECT_EQ(neurosim::testing::message_of_reading_a_fifo(
                fifo, [](const std::string& p) { read_input_file(p, 1 << 20, "mesh file"); }),
            fifo + ": mesh file: is a named pipe, not a regular file");
  EXPECT_EQ(neurosim::testing::message_of_reading_a_fifo(
                fifo, [](const std::string& p) { require_regular_file(p, 1 << 20, "image"); }),
            fifo + ": image: is a named pipe, not a regular file");
  fs::remove_all(dir);
}

TEST(InputFile, MissingFileIsNamed) {
  EXPECT_EQ(message_of([] { read_input_file("/nonexistent/x.mesh", 10, "mesh file"); }),
            "/nonexistent/x.mesh: cannot open mesh file: No such file or directory");
  EXPECT_NO_THROW(require_regular_file("/nonexistent/x.nii", 10, "image"));
}

}  // namespace
}  // namespace neurosim::common
