// Fuzz target: the recording reader (idl/wire/recording_io.cpp: length-delimited protobuf, the
// header and sample checks, the limits of RecordingLimits) on any bytes. What it refuses must be
// a std::runtime_error naming the file; what it accepts must keep its promises: the header's
// format, finite samples with non-decreasing time.
#include "fuzz/fuzz_target.hpp"
#include "idl/wire/recording_io.hpp"

#include <cmath>
#include <stdexcept>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace neurosim;
  const std::string path = fuzz::scratch_file("input.rec");
  fuzz::write_file(path, data, size);
  try {
    wire::RecordingReader reader(path);
    fuzz::require(reader.header().format() == wire::kRecordingFormat, "the header's format");
    recording::Sample s;
    double last_time_s = 0.0;
    while (reader.next(s)) {
      fuzz::require(std::isfinite(s.time_s()) && s.time_s() >= last_time_s,
                    "sample time finite and non-decreasing");
      fuzz::require(std::isfinite(s.position_m().x()) && std::isfinite(s.orientation().w()) &&
                        std::isfinite(s.force_n().z()) && std::isfinite(s.velocity_m_per_s().y()),
                    "sample values finite");
      last_time_s = s.time_s();
    }
    fuzz::require(reader.samples_read() <= size, "no more samples than bytes");
  } catch (const std::runtime_error& e) {
    fuzz::require(std::string(e.what()).find(path) != std::string::npos, "errors name the file");
  }
  return 0;
}
