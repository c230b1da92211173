// What every fuzz target shares: the libFuzzer entry point, a scratch file for readers that
// take a path, a byte cursor for targets that build structured input, and the check that
// turns a broken property into a crash the fuzzer reports.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

// The entry point libFuzzer calls (and fuzz/replay_main.cpp, for the replay tests).
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace neurosim::fuzz {

// A property the code under test promised and broke: abort, so libFuzzer keeps the input.
[[noreturn]] inline void broken(const char* property) {
  std::fprintf(stderr, "fuzz: broken property: %s\n", property);
  std::abort();
}
inline void require(bool ok, const char* property) {
  if (!ok) broken(property);
}

// This process's scratch directory (readers take paths, not buffers), removed at a normal
// exit: under $NEUROSIM_FUZZ_SCRATCH (fuzz/run sets it and removes it, also after a crash),
// else /dev/shm (a file write per input is then a memory copy), else the temporary directory.
inline const std::string& scratch_dir() {
  // Never destroyed: the clean-up at exit still reads it.
  static const std::string* dir = [] {
    const char* env = std::getenv("NEUROSIM_FUZZ_SCRATCH");
    const std::filesystem::path base = env != nullptr && *env != '\0' ? std::filesystem::path(env)
                                       : std::filesystem::is_directory("/dev/shm")
                                           ? std::filesystem::path("/dev/shm")
                                           : std::filesystem::temp_directory_path();
    // The pid zero-padded: paths of one length in every run, so the readers' messages (which
    // name the file) take the same code paths and a fixed run meets the same inputs.
    char name[32];
    std::snprintf(name, sizeof name, "neurosim_fuzz_%010d", static_cast<int>(::getpid()));
    auto* d = new std::string((base / name).string());
    std::filesystem::create_directories(*d);
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(scratch_dir(), ec);
    });
    return d;
  }();
  return *dir;
}

inline std::string scratch_file(const std::string& name) { return scratch_dir() + "/" + name; }

inline void write_file(const std::string& path, const void* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  if (!out) broken("cannot write the scratch file");
}

// Reads little-endian values from the input; past its end every value is zero.
class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  std::size_t left() const { return size_ - pos_; }
  template <class T>
  T take() {
    T v{};
    const std::size_t n = std::min(sizeof v, left());
    std::memcpy(&v, data_ + pos_, n);
    pos_ += n;
    return v;
  }
  std::uint8_t u8() { return take<std::uint8_t>(); }
  std::uint16_t u16() { return take<std::uint16_t>(); }
  std::uint32_t u32() { return take<std::uint32_t>(); }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_{0};
};

}  // namespace neurosim::fuzz
