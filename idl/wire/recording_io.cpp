#include "idl/wire/recording_io.hpp"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl.h>
#include <google/protobuf/util/delimited_message_util.h>

#include <fcntl.h>
#include <unistd.h>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

namespace neurosim::wire {

namespace {

std::string sys_error() { return std::strerror(errno); }

// One varint-length-delimited message, as ParseDelimitedFromZeroCopyStream reads it, but with
// the declared length checked against max_bytes before any of it is read.
enum class Delimited { kOk, kCleanEnd, kCorrupt, kTooLong };
Delimited read_delimited(google::protobuf::MessageLite& message,
                         google::protobuf::io::ZeroCopyInputStream* in, std::size_t max_bytes,
                         std::uint32_t& size) {
  google::protobuf::io::CodedInputStream coded(in);
  const int start = coded.CurrentPosition();
  if (!coded.ReadVarint32(&size))
    return coded.CurrentPosition() == start ? Delimited::kCleanEnd : Delimited::kCorrupt;
  if (size > max_bytes) return Delimited::kTooLong;
  const auto limit = coded.PushLimit(static_cast<int>(size));
  if (!message.MergeFromCodedStream(&coded) || !coded.ConsumedEntireMessage())
    return Delimited::kCorrupt;
  coded.PopLimit(limit);
  return Delimited::kOk;
}

void check_finite(double v, const std::string& where, const char* field) {
  if (!std::isfinite(v)) throw std::invalid_argument(where + ": " + field + " is not finite");
}

}  // namespace

void check_sample(const recording::Sample& s, double previous_time_s, const std::string& where) {
  check_finite(s.time_s(), where, "time_s");
  if (s.time_s() < previous_time_s)
    throw std::invalid_argument(where + ": time_s " + std::to_string(s.time_s()) +
                                " goes back from " + std::to_string(previous_time_s));
  const auto& p = s.position_m();
  const auto& q = s.orientation();
  const auto& f = s.force_n();
  const auto& v = s.velocity_m_per_s();
  for (double x : {p.x(), p.y(), p.z()}) check_finite(x, where, "position_m");
  for (double x : {q.w(), q.x(), q.y(), q.z()}) check_finite(x, where, "orientation");
  for (double x : {f.x(), f.y(), f.z()}) check_finite(x, where, "force_n");
  for (double x : {v.x(), v.y(), v.z()}) check_finite(x, where, "velocity_m_per_s");
}

// ---------------------------------------------------------------------------------------------
struct RecordingWriter::Impl {
  std::string file;     // the name readers see, only ever a complete recording
  std::string partial;  // written here, renamed to `file` by close()
  int fd = -1;
  std::unique_ptr<google::protobuf::io::FileOutputStream> out;

  // An I/O error: the partial file is removed (nothing half-written is left to be read back
  // later, and a full disk gets its space back) and the error is thrown, naming the file.
  [[noreturn]] void fail(const std::string& what, int err) {
    if (out) {
      out->SetCloseOnDelete(false);
      out.reset();
    }
    if (fd >= 0) ::close(fd);
    fd = -1;
    ::unlink(partial.c_str());
    throw std::runtime_error("recording " + file + ": " + what + ": " + std::strerror(err) +
                             " (nothing kept)");
  }
};

RecordingWriter::RecordingWriter(const std::filesystem::path& file, recording::Header header)
    : impl_(std::make_unique<Impl>()) {
  impl_->file = file.string();
  impl_->partial = impl_->file + ".partial";
  impl_->fd = ::open(impl_->partial.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (impl_->fd < 0)
    throw std::runtime_error("recording " + impl_->file + ": cannot create " + impl_->partial +
                             ": " + sys_error());
  impl_->out = std::make_unique<google::protobuf::io::FileOutputStream>(impl_->fd);
  header.set_format(kRecordingFormat);
  if (!google::protobuf::util::SerializeDelimitedToZeroCopyStream(header, impl_->out.get()))
    impl_->fail("cannot write header", impl_->out->GetErrno());
}

RecordingWriter::~RecordingWriter() {
  try {
    close();
  } catch (...) {  // destructor: close() reports errors to callers who ask
  }
}

void RecordingWriter::write(const recording::Sample& sample) {
  if (!impl_->out) throw std::logic_error("recording " + impl_->file + ": write after close");
  check_sample(sample, last_time_s_,
               "recording " + impl_->file + ": sample " + std::to_string(count_));
  if (!google::protobuf::util::SerializeDelimitedToZeroCopyStream(sample, impl_->out.get()))
    impl_->fail("cannot write sample " + std::to_string(count_), impl_->out->GetErrno());
  last_time_s_ = sample.time_s();
  ++count_;
}

void RecordingWriter::close() {
  if (!impl_ || !impl_->out) return;
  if (!impl_->out->Flush()) impl_->fail("cannot write", impl_->out->GetErrno());
  if (::fsync(impl_->fd) != 0) impl_->fail("cannot write", errno);
  impl_->out.reset();  // the stream does not own the descriptor
  if (::close(impl_->fd) != 0) {
    impl_->fd = -1;
    impl_->fail("cannot close", errno);
  }
  impl_->fd = -1;
  if (::rename(impl_->partial.c_str(), impl_->file.c_str()) != 0)
    impl_->fail("cannot rename " + impl_->partial + " to it", errno);
}

// ---------------------------------------------------------------------------------------------
struct RecordingReader::Impl {
  std::string file;
  std::unique_ptr<google::protobuf::io::FileInputStream> in;
};

RecordingReader::RecordingReader(const std::filesystem::path& file, RecordingLimits limits)
    : impl_(std::make_unique<Impl>()), limits_(limits) {
  impl_->file = file.string();
  const int fd = ::open(impl_->file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("recording " + impl_->file + ": cannot open: " + sys_error());
  impl_->in = std::make_unique<google::protobuf::io::FileInputStream>(fd);
  impl_->in->SetCloseOnDelete(true);
  std::uint32_t size = 0;
  switch (read_delimited(header_, impl_->in.get(), limits_.max_header_bytes, size)) {
    case Delimited::kOk:
      break;
    case Delimited::kCleanEnd:
      throw std::runtime_error("recording " + impl_->file + ": empty file, no header");
    case Delimited::kCorrupt:
      throw std::runtime_error("recording " + impl_->file + ": header is truncated or corrupt");
    case Delimited::kTooLong:
      throw std::runtime_error("recording " + impl_->file + ": header length " +
                               std::to_string(size) + " bytes is above the limit of " +
                               std::to_string(limits_.max_header_bytes) +
                               " (not a neurosim recording?)");
  }
  if (header_.format() != kRecordingFormat)
    throw std::runtime_error("recording " + impl_->file + ": not a neurosim recording (format '" +
                             header_.format() + "', expected '" + kRecordingFormat + "')");
}

RecordingReader::~RecordingReader() = default;

bool RecordingReader::next(recording::Sample& sample) {
  const auto offset = impl_->in->ByteCount();
  const std::string where = "recording " + impl_->file + ": sample " + std::to_string(count_) +
                            " (byte offset " + std::to_string(offset) + ")";
  if (static_cast<std::size_t>(offset) > limits_.max_file_bytes)
    throw std::runtime_error(where + ": the file is larger than the limit of " +
                             std::to_string(limits_.max_file_bytes) +
                             " bytes (a stream that does not end?)");
  sample.Clear();  // the parser merges into what is there
  std::uint32_t size = 0;
  switch (read_delimited(sample, impl_->in.get(), limits_.max_sample_bytes, size)) {
    case Delimited::kOk:
      break;
    case Delimited::kCleanEnd:
      return false;
    case Delimited::kCorrupt:
      throw std::runtime_error(where + " is truncated or corrupt; " + std::to_string(count_) +
                               " samples before it are good");
    case Delimited::kTooLong:
      throw std::runtime_error(where + ": length " + std::to_string(size) +
                               " bytes is above the limit of " +
                               std::to_string(limits_.max_sample_bytes) + " for a sample");
  }
  if (count_ >= limits_.max_samples)
    throw std::runtime_error(where + ": more than " + std::to_string(limits_.max_samples) +
                             " samples, the limit of a recording");
  try {
    check_sample(sample, last_time_s_,
                 "recording " + impl_->file + ": sample " + std::to_string(count_));
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string(e.what()) + " (byte offset " + std::to_string(offset) + ")");
  }
  last_time_s_ = sample.time_s();
  ++count_;
  return true;
}

Recording read_recording(const std::filesystem::path& file, RecordingLimits limits) {
  try {
    RecordingReader r(file, limits);
    Recording rec;
    rec.header = r.header();
    recording::Sample s;
    while (r.next(s)) rec.samples.push_back(s);
    return rec;
  } catch (const std::bad_alloc&) {
    throw std::runtime_error("recording " + file.string() + ": out of memory while reading");
  }
}

}  // namespace neurosim::wire
