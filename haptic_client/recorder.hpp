// Session recording (recording.proto through wire::RecordingWriter): the loop pushes plain
// samples into a lock-free ring; a background thread serialises and writes them, so the 1 kHz
// loop never touches the file.
#pragma once

#include "recording.pb.h"

#include <Eigen/Core>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::haptic {

struct RecordSample {
  double time_s = 0;  // nominal tick time since start (tick index × period), unit s
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Vector4d orientation = Eigen::Vector4d(1, 0, 0, 0);
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();
  std::uint32_t buttons = 0;
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // force commanded to the device, unit N
  std::uint64_t contact_model_sequence = 0;
  std::uint64_t tool_sequence = 0;
  bool in_contact = false;
};

class Recorder {
 public:
  // blocking: push() waits for room instead of dropping (simulated-time runs, faster than real).
  Recorder(const std::string& file, recording::Header header, bool blocking = false,
           std::size_t capacity = 8192);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Loop thread: never allocates; returns false (and counts) when the ring is full.
  bool push(const RecordSample& s);
  // Flushes everything and closes the file; rethrows a writer error.
  void close();
  std::uint64_t dropped() const { return dropped_.load(); }
  std::uint64_t written() const { return written_.load(); }
  // The writer hit an I/O error (disk full, read-only folder): it stopped, said so on stderr at
  // once and removed the partial file; the loop goes on and push() drops (counted).
  bool failed() const { return failed_.load(std::memory_order_acquire); }

 private:
  void run();

  std::string file_;
  std::vector<RecordSample> ring_;
  std::atomic<std::uint64_t> head_{0};  // next slot to write (producer)
  std::atomic<std::uint64_t> tail_{0};  // next slot to read (consumer)
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> written_{0};
  bool blocking_;
  struct Writer;
  std::unique_ptr<Writer> writer_;
  std::atomic<bool> failed_{false};
  std::mutex error_mutex_;
  std::string error_;  // set once under error_mutex_ before failed_
  std::thread thread_;
  bool closed_ = false;
};

}  // namespace neurosim::haptic
