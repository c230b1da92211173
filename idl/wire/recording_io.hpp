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

// Bounds on what a reader accepts (hostile input: a file that never ends, or one whose length
// prefixes claim gigabytes). A written Sample is about 130 bytes; a session at 1 kHz for 4 hours
// is 14.4 million samples and about 2 GB.
struct RecordingLimits {
  std::size_t max_header_bytes = std::size_t{64} << 10;  // declared length of the Header, bytes
  std::size_t max_sample_bytes = 1024;                   // declared length of one Sample, bytes
  std::size_t max_samples = 14'400'000;                  // 4 h at 1 kHz
  std::size_t max_file_bytes = std::size_t{4} << 30;     // unit bytes
};

// Writes a recording. The header's format field is set here; samples are checked (finite
// values, non-decreasing time) before they are written. Throws std::runtime_error on I/O errors
// and std::invalid_argument on bad samples, naming the file and sample index.
// The samples go to "<file>.partial"; close() flushes, syncs and renames it to <file>, so <file>
// only ever holds a complete recording (a crash leaves the .partial, never a cut <file>). An I/O
// error (disk full, read-only folder) removes the .partial: nothing half-written is kept.
class RecordingWriter {
 public:
  RecordingWriter(const std::filesystem::path& file, recording::Header header);
  ~RecordingWriter();  // closes (and renames); errors here are lost: call close() to see them
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
// file, the sample index and the byte offset when a sample is truncated or corrupt, or when a
// length prefix, the sample count or the file size is beyond `limits` (checked before anything
// is read into memory for it: the reader holds one message at a time).
class RecordingReader {
 public:
  explicit RecordingReader(const std::filesystem::path& file, RecordingLimits limits = {});
  ~RecordingReader();
  RecordingReader(const RecordingReader&) = delete;
  RecordingReader& operator=(const RecordingReader&) = delete;

  const recording::Header& header() const { return header_; }
  bool next(recording::Sample& sample);
  std::size_t samples_read() const { return count_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  RecordingLimits limits_;
  recording::Header header_;
  std::size_t count_ = 0;
  double last_time_s_ = 0;
};

struct Recording {
  recording::Header header;
  std::vector<recording::Sample> samples;
};

// Whole file at once (throws as RecordingReader does; running out of memory is a
// std::runtime_error naming the file).
Recording read_recording(const std::filesystem::path& file, RecordingLimits limits = {});

// Throws std::invalid_argument("<where>: ...") if a field is not finite or time goes backwards.
void check_sample(const recording::Sample& s, double previous_time_s, const std::string& where);

}  // namespace neurosim::wire
