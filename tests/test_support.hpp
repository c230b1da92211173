// Small helpers shared by the tests.
#pragma once

#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>

namespace neurosim::testing {

// Root of the source tree (scenes/, tests/data/, bench/data/).
inline std::filesystem::path source_dir() { return NEUROSIM_SOURCE_DIR; }
// Where the built programs are (build/bin).
inline std::filesystem::path bin_dir() { return NEUROSIM_BIN_DIR; }

// A fresh, empty temporary directory unique to this process and tag.
inline std::filesystem::path temp_dir(const std::string& tag) {
  std::random_device rd;
  auto dir = std::filesystem::temp_directory_path() /
             ("neurosim_" + tag + "_" + std::to_string(rd()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// The message of the exception f throws, or "" if it throws none.
inline std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// The whole content of a text file ("" when it cannot be read: the caller's assertion says what
// was expected).
inline std::string slurp(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace neurosim::testing
