// Recorder: what the loop pushes is what an independent reader (wire::read_recording) finds in
// the file, field by field (position, orientation w x y z, velocity, buttons, force, sequences,
// contact) and in order, also when the ring wraps many times; a blocking recorder drops
// nothing; a sample the writer refuses makes close() throw naming the file and the sample; a
// folder that does not exist is refused at once, naming the file.
#include "haptic_client/recorder.hpp"

#include "idl/wire/recording_io.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <limits>

namespace fs = std::filesystem;
namespace nh = neurosim::haptic;
namespace rec = neurosim::recording;

namespace {

rec::Header header() {
  rec::Header h;
  h.set_scene_name("cube_cylinder");
  h.set_station_id("omni-1");
  h.set_tool_id("probe");
  h.set_sample_rate_hz(1000);
  return h;
}

// Every field different and different per sample (a swapped or dropped field shows).
nh::RecordSample sample(int i) {
  nh::RecordSample s;
  const double k = static_cast<double>(i);
  s.time_s = 1e-3 * k;
  s.position_m = {0.01 + 1e-5 * k, -0.02 - 2e-5 * k, 0.03 + 3e-5 * k};
  s.orientation = Eigen::Vector4d(0.5 + 1e-4 * k, 0.1, -0.2, 0.3).normalized();
  s.velocity_m_per_s = {1e-3 * k, -2e-3, 4e-3};
  s.buttons = static_cast<std::uint32_t>(i % 4);
  s.force_n = {0.1, -0.2 * k, 0.3 + k};
  s.contact_model_sequence = 1000 + 3 * static_cast<std::uint64_t>(i);
  s.tool_sequence = 7 + static_cast<std::uint64_t>(i);
  s.in_contact = (i % 3) == 1;
  return s;
}

void expect_same(const nh::RecordSample& s, const rec::Sample& r, int i) {
  SCOPED_TRACE("sample " + std::to_string(i));
  EXPECT_EQ(r.time_s(), s.time_s);
  EXPECT_EQ(r.position_m().x(), s.position_m.x());
  EXPECT_EQ(r.position_m().y(), s.position_m.y());
  EXPECT_EQ(r.position_m().z(), s.position_m.z());
  EXPECT_EQ(r.orientation().w(), s.orientation[0]);
  EXPECT_EQ(r.orientation().x(), s.orientation[1]);
  EXPECT_EQ(r.orientation().y(), s.orientation[2]);
  EXPECT_EQ(r.orientation().z(), s.orientation[3]);
  EXPECT_EQ(r.velocity_m_per_s().x(), s.velocity_m_per_s.x());
  EXPECT_EQ(r.velocity_m_per_s().y(), s.velocity_m_per_s.y());
  EXPECT_EQ(r.velocity_m_per_s().z(), s.velocity_m_per_s.z());
  EXPECT_EQ(r.buttons(), s.buttons);
  EXPECT_EQ(r.force_n().x(), s.force_n.x());
  EXPECT_EQ(r.force_n().y(), s.force_n.y());
  EXPECT_EQ(r.force_n().z(), s.force_n.z());
  EXPECT_EQ(r.contact_model_sequence(), s.contact_model_sequence);
  EXPECT_EQ(r.tool_sequence(), s.tool_sequence);
  EXPECT_EQ(r.in_contact(), s.in_contact);
}

TEST(haptic_recorder, EveryFieldReachesTheFileInOrder) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_recorder_fields");
  const fs::path file = dir / "session.rec";
  constexpr int kSamples = 50;
  {
    nh::Recorder r(file.string(), header(), /*blocking=*/true);
    for (int i = 0; i < kSamples; ++i) ASSERT_TRUE(r.push(sample(i)));
    r.close();
    EXPECT_EQ(r.written(), static_cast<std::uint64_t>(kSamples));
    EXPECT_EQ(r.dropped(), 0u);
    EXPECT_FALSE(r.failed());
  }
  const neurosim::wire::Recording got = neurosim::wire::read_recording(file);
  EXPECT_EQ(got.header.format(), neurosim::wire::kRecordingFormat);
  EXPECT_EQ(got.header.station_id(), "omni-1");
  EXPECT_EQ(got.header.tool_id(), "probe");
  ASSERT_EQ(got.samples.size(), static_cast<std::size_t>(kSamples));
  for (int i = 0; i < kSamples; ++i) expect_same(sample(i), got.samples[i], i);
  fs::remove_all(dir);
}

// A ring of two slots, 600 samples: the blocking producer waits for the writer each time the
// ring is full; nothing is lost or reordered across 300 wrap-arounds.
TEST(haptic_recorder, BlockingRecorderThroughATinyRingDropsNothing) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_recorder_ring");
  const fs::path file = dir / "ring.rec";
  constexpr int kSamples = 600;
  {
    nh::Recorder r(file.string(), header(), /*blocking=*/true, /*capacity=*/2);
    for (int i = 0; i < kSamples; ++i) ASSERT_TRUE(r.push(sample(i))) << i;
    r.close();
    EXPECT_EQ(r.dropped(), 0u);
    EXPECT_EQ(r.written(), static_cast<std::uint64_t>(kSamples));
  }
  const auto got = neurosim::wire::read_recording(file);
  ASSERT_EQ(got.samples.size(), static_cast<std::size_t>(kSamples));
  for (int i = 0; i < kSamples; ++i) {
    ASSERT_EQ(got.samples[i].tool_sequence(), sample(i).tool_sequence) << i;
    ASSERT_EQ(got.samples[i].time_s(), sample(i).time_s) << i;
  }
  fs::remove_all(dir);
}

TEST(haptic_recorder, RefusedSampleMakesCloseThrowNamingFileAndSample) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_recorder_bad");
  const fs::path file = dir / "bad.rec";
  nh::Recorder r(file.string(), header(), /*blocking=*/true);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(r.push(sample(i)));
  nh::RecordSample bad = sample(5);
  bad.force_n.y() = std::numeric_limits<double>::quiet_NaN();
  ASSERT_TRUE(r.push(bad));
  std::string m;
  try {
    r.close();
  } catch (const std::runtime_error& e) {
    m = e.what();
  }
  EXPECT_TRUE(r.failed());
  EXPECT_NE(m.find(file.string()), std::string::npos) << m;
  EXPECT_NE(m.find("sample 5"), std::string::npos) << m;
  EXPECT_NE(m.find("not finite"), std::string::npos) << m;
  EXPECT_EQ(r.written(), 5u);
  r.close();  // a second close is a no-op
  fs::remove_all(dir);
}

TEST(haptic_recorder, MissingFolderIsRefusedNamingTheFile) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_recorder_missing");
  const fs::path file = dir / "no_such_folder" / "r.rec";
  const std::string m =
      neurosim::testing::message_of([&] { nh::Recorder r(file.string(), header()); });
  EXPECT_NE(m.find(file.string()), std::string::npos) << m;
  EXPECT_FALSE(fs::exists(file));
  fs::remove_all(dir);
}

}  // namespace
