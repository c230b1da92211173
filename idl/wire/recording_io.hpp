// Recorded trajectories (idl/recording.proto): one Header, then Samples, each length-delimited.
#pragma once

#include "recording.pb.h"

#include <cstddef>
#include <filesystem>
#include <memory>
#include <vector>

namespace neurosim::wire {

// Header.format of every file this code writes and accepts.
inline constexpr const char* kRecordingFormat = "neurosim.recording/1";

// Writes a recording. The header's format field is set here; samples are checked (finite
// values, non-decreasing time) before they are written. Throws std::runtime_error on I/O errors
// and std::invalid_argument on bad samples, naming the file and sample index.
class RecordingWriter {
 public:
  RecordingWriter(const std::filesystem::path& file, recording::Header header);
  ~RecordingWriter();  // closes; errors at this point are lost: call close() to see them
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  void write(const recording::Sample& sample);
  void close();
  std::size_t samples_written() const { return count_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::size_t count_ = 0;
  double last_time_s_ = 0;
};

// Reads a recording written by RecordingWriter. The constructor reads and checks the header.
// next() returns false at the clean end of the file and throws std::runtime_error naming the
// file, the sample index and the byte offset when a sample is truncated or corrupt.
class RecordingReader {
 public:
  explicit RecordingReader(const std::filesystem::path& file);
  ~RecordingReader();
  RecordingReader(const RecordingReader&) = delete;
  RecordingReader& operator=(const RecordingReader&) = delete;

  const recording::Header& header() const { return header_; }
  bool next(recording::Sample& sample);
  std::size_t samples_read() const { return count_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  recording::Header header_;
  std::size_t count_ = 0;
  double last_time_s_ = 0;
};

struct Recording {
  recording::Header header;
  std::vector<recording::Sample> samples;
};

// Whole file at once (throws as RecordingReader does).
Recording read_recording(const std::filesystem::path& file);

// Throws std::invalid_argument("<where>: ...") if a field is not finite or time goes backwards.
void check_sample(const recording::Sample& s, double previous_time_s, const std::string& where);

}  // namespace neurosim::wire
