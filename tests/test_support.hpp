// Small helpers shared by the tests.
#pragma once

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
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
#include <thread>

namespace neurosim::testing {

// Root of the source tree (scenes/, tests/data/, bench/data/).
inline std::filesystem::path source_dir() { return NEUROSIM_SOURCE_DIR; }
// Where the built programs are (build/bin).
inline std::filesystem::path bin_dir() { return NEUROSIM_BIN_DIR; }
// The folder one ctest run's tests share for the hosts' factors and boundary operators (pass
// it as neurosim-server's --cache-dir or SimulationOptions::compliance_cache_dir): emptied before
// every ctest run (tests/CMakeLists.txt, test_cache_clear), filled by the first test that builds
// a host, read by the next. Only for tests that do not test the cache itself.
inline std::filesystem::path shared_cache_dir() { return NEUROSIM_TEST_CACHE_DIR; }
#ifdef NEUROSIM_BRAIN7_DIR
// A scene of the tests' 7 mm brains ("brain_artery", "brain_skull"; neurosim-model --cell-size 7,
// built at build time: tests/CMakeLists.txt, neurosim_use_brain7) for tests that need a brain,
// not the bundled 5 mm one.
inline std::filesystem::path brain7_scene(const std::string& name) {
  return std::filesystem::path(NEUROSIM_BRAIN7_DIR) / (name + ".scene");
}
#endif

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

// Whether text contains part: EXPECT_PRED2(contains, message, part) prints both when it fails.
inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A file `name` holding `text` in a fresh temporary directory of `tag` (temp_dir); its path.
inline std::filesystem::path write_temp_file(const std::string& tag, const std::string& name,
                                             const std::string& text) {
  const auto file = temp_dir(tag) / name;
  std::ofstream(file) << text;
  return file;
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

// A named pipe no one writes to, at path, and the message of read(path) run on a thread. A reader
// that blocks on the pipe (opening it for reading waits for a writer) is released after
// timeout_s by a writer that opens and closes it, so a broken reader fails the test (its
// message then starts with "blocked:") instead of hanging it.
inline std::string message_of_reading_a_fifo(const std::string& path,
                                             const std::function<void(const std::string&)>& read,
                                             double timeout_s = 10.0) {
  if (::mkfifo(path.c_str(), 0600) != 0) return "cannot make the FIFO " + path;
  std::string message;
  std::atomic<bool> done{false};
  std::thread reader([&] {
    message = message_of([&] { read(path); });
    done.store(true);
  });
  const auto t0 = std::chrono::steady_clock::now();
  while (!done.load() &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < timeout_s)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const bool blocked = !done.load();
  while (!done.load()) {  // release it: a writer comes and goes (end of file for the reader)
    const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  reader.join();
  std::filesystem::remove(path);
  return blocked ? "blocked: " + message : message;
}

}  // namespace neurosim::testing
