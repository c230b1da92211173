// Small helpers shared by the tests.
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <new>
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

// Runs f in a forked child whose address space may grow by at most extra_bytes, and returns
// the message of the exception f throws ("" if none). A std::bad_alloc that escapes f, or a
// child that dies, gives a message saying so, which no expectation on a named error matches:
// hostile input must be refused (or run out of memory with an error naming it), never crash.
inline std::string message_with_memory_limit(std::size_t extra_bytes,
                                             const std::function<void()>& f) {
  int fds[2];
  if (::pipe(fds) != 0) return "pipe failed";
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0) return "fork failed";
  if (pid == 0) {
    ::close(fds[0]);
    long pages = 0;
    std::ifstream("/proc/self/statm") >> pages;  // current address space, unit pages
    rlimit limit{};
    limit.rlim_cur = limit.rlim_max =
        static_cast<rlim_t>(pages) * static_cast<rlim_t>(::sysconf(_SC_PAGESIZE)) + extra_bytes;
    std::string message;
    if (::setrlimit(RLIMIT_AS, &limit) != 0) {
      message = "setrlimit failed";
    } else {
      try {
        f();
      } catch (const std::bad_alloc&) {
        message = "std::bad_alloc escaped";
      } catch (const std::exception& e) {
        message = e.what();
      }
    }
    const char* p = message.data();
    for (std::size_t left = message.size(); left > 0;) {
      const ssize_t n = ::write(fds[1], p, left);
      if (n <= 0) break;
      p += n;
      left -= static_cast<std::size_t>(n);
    }
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string message;
  char buf[4096];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;)
    message.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    message += " (child died, status " + std::to_string(status) + ")";
  return message;
}

}  // namespace neurosim::testing
