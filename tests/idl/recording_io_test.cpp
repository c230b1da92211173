// Recordings (idl/recording.proto): round trip, truncated and corrupt files give errors that
// name the file and the sample, bad samples are refused on write.
#include "idl/wire/recording_io.hpp"
#include "test_support.hpp"

#include <google/protobuf/util/delimited_message_util.h>
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

namespace ns = neurosim::wire;
namespace rec = neurosim::recording;

namespace {

rec::Header header() {
  rec::Header h;
  h.set_scene_name("cube_cylinder");
  h.set_scene_file("scenes/cube_cylinder.scene");
  h.set_station_id("omni-1");
  h.set_tool_id("probe");
  h.mutable_device()->set_kind("script:press");
  h.mutable_device()->set_max_force_n(3.3);
  h.set_start_time_unix_ns(1700000000000000000);
  h.set_sample_rate_hz(1000);
  h.set_server_step_hz(1000);
  h.set_label("made with script:press");
  return h;
}

rec::Sample sample(std::size_t i) {
  rec::Sample s;
  const double t = 1e-3 * static_cast<double>(i);
  s.set_time_s(t);
  s.mutable_position_m()->set_x(0.01 * std::sin(t));
  s.mutable_position_m()->set_y(0.002);
  s.mutable_position_m()->set_z(-0.001 * t);
  s.mutable_orientation()->set_w(1);
  s.set_buttons(static_cast<std::uint32_t>(i % 2));
  s.mutable_force_n()->set_z(0.5 * t);
  s.set_contact_model_sequence(i > 0 ? i - 1 : 0);
  s.set_tool_sequence(i + 1);
  s.set_in_contact(i > 500);
  return s;
}

std::filesystem::path write_file(const std::filesystem::path& dir, std::size_t n) {
  const auto file = dir / "press.rec";
  ns::RecordingWriter w(file, header());
  for (std::size_t i = 0; i < n; ++i) w.write(sample(i));
  EXPECT_EQ(w.samples_written(), n);
  w.close();
  return file;
}

template <class F>
std::string error_of(F f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(wire_recording, RoundTrip) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  const auto file = write_file(dir, 1000);
  const ns::Recording r = ns::read_recording(file);
  EXPECT_EQ(r.header.format(), ns::kRecordingFormat);
  EXPECT_EQ(r.header.label(), "made with script:press");
  EXPECT_EQ(r.header.station_id(), "omni-1");
  EXPECT_EQ(r.header.device().kind(), "script:press");
  ASSERT_EQ(r.samples.size(), 1000u);
  for (std::size_t i = 0; i < r.samples.size(); ++i) {
    const rec::Sample want = sample(i);
    ASSERT_EQ(r.samples[i].SerializeAsString(), want.SerializeAsString()) << "sample " << i;
  }
  std::filesystem::remove_all(dir);
}

TEST(wire_recording, TruncatedFileNamesFileAndSample) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  const auto file = write_file(dir, 100);
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 3);
  ns::RecordingReader r(file);
  rec::Sample s;
  std::size_t n = 0;
  const std::string err = error_of([&] {
    while (r.next(s)) ++n;
  });
  EXPECT_EQ(n, 99u);
  EXPECT_NE(err.find(file.string()), std::string::npos) << err;
  EXPECT_NE(err.find("sample 99"), std::string::npos) << err;
  EXPECT_NE(err.find("truncated"), std::string::npos) << err;
  std::filesystem::remove_all(dir);
}

TEST(wire_recording, CorruptOrForeignFilesAreRefused) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  // Empty file.
  const auto empty = dir / "empty.rec";
  std::ofstream(empty).close();
  EXPECT_NE(error_of([&] { ns::RecordingReader r(empty); }).find("no header"), std::string::npos);
  // Not a recording (text).
  const auto text = dir / "scene.txt";
  std::ofstream(text) << "name: \"cube\"\nmeshes { id: \"a\" }\n";
  const std::string e1 = error_of([&] { ns::RecordingReader r(text); });
  EXPECT_NE(e1.find(text.string()), std::string::npos) << e1;
  // Garbage where sample 10 starts: a 5-byte message that is not valid protobuf.
  const auto offset = std::filesystem::file_size(write_file(dir, 10));
  const auto file = write_file(dir, 20);
  {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(offset));
    const char junk[6] = {'\x05', '\xff', '\xff', '\xff', '\xff', '\xff'};
    f.write(junk, 6);
  }
  const std::string e2 = error_of([&] { ns::read_recording(file); });
  EXPECT_NE(e2.find(file.string()), std::string::npos) << e2;
  EXPECT_NE(e2.find("sample 10"), std::string::npos) << e2;
  EXPECT_NE(e2.find("corrupt"), std::string::npos) << e2;
  std::filesystem::remove_all(dir);
}

TEST(wire_recording, BadSamplesAreRefusedOnWrite) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  ns::RecordingWriter w(dir / "bad.rec", header());
  w.write(sample(5));
  rec::Sample back = sample(4);  // time goes backwards
  EXPECT_THROW(w.write(back), std::invalid_argument);
  rec::Sample nan = sample(6);
  nan.mutable_force_n()->set_x(std::numeric_limits<double>::quiet_NaN());
  const std::string err = error_of([&] { w.write(nan); });
  EXPECT_NE(err.find("force_n"), std::string::npos) << err;
  EXPECT_NE(err.find("sample 1"), std::string::npos) << err;
  w.close();
  EXPECT_EQ(ns::read_recording(dir / "bad.rec").samples.size(), 1u);
  EXPECT_THROW(ns::RecordingWriter(dir / "no/such/dir/x.rec", header()), std::runtime_error);
  std::filesystem::remove_all(dir);
}

// Hostile length prefixes: refused by their declared length, before anything is read for them.
TEST(wire_recording, LengthPrefixesBeyondTheLimitsAreRefused) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  const auto huge_header = dir / "huge_header.rec";
  std::ofstream(huge_header, std::ios::binary) << std::string("\xff\xff\xff\xff\x07", 5) << "abc";
  const std::string e1 = error_of([&] { ns::RecordingReader r(huge_header); });
  EXPECT_NE(e1.find(huge_header.string() + ": header length 2147483647 bytes is above the limit of "
                                           "65536"),
            std::string::npos)
      << e1;

  // Sample 10 claims 1e9 bytes (varint 0x80 0x94 0xeb 0xdc 0x03), the file has 3 more.
  const auto file = write_file(dir, 10);
  std::ofstream(file, std::ios::binary | std::ios::app)
      << std::string("\x80\x94\xeb\xdc\x03", 5) << "abc";
  const std::string e2 = error_of([&] { ns::read_recording(file); });
  EXPECT_NE(e2.find("sample 10"), std::string::npos) << e2;
  EXPECT_NE(e2.find("length 1000000000 bytes is above the limit of 1024"), std::string::npos) << e2;

  // A well-formed sample that is too long: 2000 bytes of an unknown field (number 100).
  const auto big = dir / "big_sample.rec";
  std::filesystem::copy_file(write_file(dir, 10), big);
  std::string unknown =
      std::string("\xa2\x06", 2) + std::string("\xd0\x0f", 2) + std::string(2000, 'x');
  std::ofstream(big, std::ios::binary | std::ios::app)
      << std::string("\xd4\x0f", 2) << unknown;  // length 2004
  const std::string e3 = error_of([&] { ns::read_recording(big); });
  EXPECT_NE(e3.find("sample 10"), std::string::npos) << e3;
  EXPECT_NE(e3.find("length 2004 bytes is above the limit of 1024"), std::string::npos) << e3;
  std::filesystem::remove_all(dir);
}

// A recording that never ends (a FIFO whose writer repeats a sample) stops at the sample and
// byte limits instead of filling memory.
TEST(wire_recording, EndlessStreamStopsAtTheLimits) {
  const auto dir = neurosim::testing::temp_dir("wire_rec");
  const std::string head = neurosim::testing::slurp(write_file(dir, 0));
  std::ostringstream one;
  google::protobuf::util::SerializeDelimitedToOstream(sample(1), &one);
  const std::string repeated = one.str();
  std::signal(SIGPIPE, SIG_IGN);  // the writer learns that the reader left through EPIPE
  const auto endless = [&](const ns::RecordingLimits& limits) {
    const auto fifo = dir / "endless.rec";
    std::filesystem::remove(fifo);
    EXPECT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    std::thread writer([&] {
      const int fd = ::open(fifo.c_str(), O_WRONLY);
      if (fd < 0) return;
      std::string block = head;
      for (int i = 0; i < 64; ++i) block += repeated;
      if (::write(fd, block.data(), block.size()) > 0) {
        block = std::string();
        for (int i = 0; i < 64; ++i) block += repeated;
        while (::write(fd, block.data(), block.size()) > 0) {
        }
      }
      ::close(fd);
    });
    const std::string e = error_of([&] { ns::read_recording(fifo, limits); });
    writer.join();
    return e;
  };
  ns::RecordingLimits few_samples;
  few_samples.max_samples = 1000;
  const std::string e1 = endless(few_samples);
  EXPECT_NE(e1.find("sample 1000"), std::string::npos) << e1;
  EXPECT_NE(e1.find("more than 1000 samples"), std::string::npos) << e1;
  ns::RecordingLimits few_bytes;
  few_bytes.max_file_bytes = 1 << 16;
  const std::string e2 = endless(few_bytes);
  EXPECT_NE(e2.find("larger than the limit of 65536 bytes"), std::string::npos) << e2;
  std::filesystem::remove_all(dir);
}
