// Helpers of the viewer tests: an Xvfb display for VTK (X only on these machines), child
// processes (neurosim-server, neurosim-viewer) with logs, and the brain press point.
#pragma once

#include "common/clock.hpp"
#include "test_support.hpp"
#include "viewer_client/viewer/state.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

// Two Xlib calls, declared here rather than by <X11/Xlib.h>, whose macros (Success, Status, None)
// collide with Eigen and VTK names in the tests that include this header.
extern "C" {
struct _XDisplay;
_XDisplay* XOpenDisplay(const char* display_name);
int XCloseDisplay(_XDisplay* display);
}

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace neurosim::testing {

using neurosim::common::seconds_since;


// A child process with stdout+stderr into a log file; killed (SIGKILL) when destroyed.
class Child {
 public:
  Child(std::vector<std::string> args, const std::filesystem::path& log) : log_(log) {
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    const int rc = posix_spawn(&pid_, args[0].c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + args[0]);
  }
  ~Child() { kill(SIGKILL); }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  // Sends sig and waits; returns the wait status (-1 if it was not running).
  int kill(int sig) {
    if (pid_ <= 0) return status_;
    ::kill(pid_, sig);
    waitpid(pid_, &status_, 0);
    pid_ = 0;
    return status_;
  }
  // Waits up to timeout_s for the process to end; true if it ended (status in status()).
  bool wait(double timeout_s) {
    const auto t0 = std::chrono::steady_clock::now();
    while (pid_ > 0) {
      if (waitpid(pid_, &status_, WNOHANG) == pid_) {
        pid_ = 0;
        return true;
      }
      if (seconds_since(t0) > timeout_s) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return true;
  }
  bool running() {
    if (pid_ <= 0) return false;
    if (waitpid(pid_, &status_, WNOHANG) == pid_) {
      pid_ = 0;
      return false;
    }
    return true;
  }
  int status() const { return status_; }
  std::string log() const { return slurp(log_); }
  // Waits until the log contains `text` at least `count` times.
  bool wait_for_log(const std::string& text, double timeout_s, int count = 1) {
    const auto t0 = std::chrono::steady_clock::now();
    while (seconds_since(t0) < timeout_s) {
      const std::string l = log();
      int n = 0;
      for (auto p = l.find(text); p != std::string::npos; p = l.find(text, p + 1)) ++n;
      if (n >= count) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }

 private:
  std::filesystem::path log_;
  pid_t pid_ = 0;
  int status_ = -1;
};

// An Xvfb server on a display of its own; sets DISPLAY for this process and its children.
// The display number is derived from the pid (not the first free one, as -displayfd alone would
// pick): a server of another test that is shutting down unlinks its socket after its lock file,
// and a new server on that same number then loses its socket ("bad X server connection").
// -displayfd still reports when the server accepts connections; a number in use makes Xvfb exit,
// and the next one is tried. A display that reported but refuses an X connection (seen once under
// two CPU hogs: VTK's "bad X server connection", then the aborted test's Xvfb kept ctest's output
// pipe open until the timeout) is stopped and the next number tried; Xvfb's output goes to
// /dev/null so it never holds the test's output open. -noreset: by default an X server resets
// when its last client disconnects, and a client connecting during the reset is refused; a test
// that opens and closes several render windows (or this helper's own check) then loses the race.
class Xvfb {
 public:
  Xvfb() {
    for (int attempt = 0; attempt < 50; ++attempt) {
      const int number = 300 + static_cast<int>((getpid() + 7919 * attempt) % 4000);
      if (start(number)) return;
    }
    throw std::runtime_error("Xvfb did not start on any of 50 displays");
  }
  ~Xvfb() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
    }
  }
  const std::string& display() const { return display_; }

 private:
  pid_t pid_ = 0;
  std::string display_;

  // True when an X client can open the display (tried for up to 2 s).
  static bool accepts_connection(const std::string& display) {
    for (int attempt = 0; attempt < 20; ++attempt) {
      if (_XDisplay* d = XOpenDisplay(display.c_str())) {
        XCloseDisplay(d);
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }

  // True when Xvfb runs on :number and accepts connections; false (nothing left running) when it
  // exited, e.g. because the display is taken.
  bool start(int number) {
    int fds[2];
    if (pipe(fds) != 0) throw std::runtime_error("pipe failed");
    const std::string fd = std::to_string(fds[1]);
    std::vector<std::string> args{"/usr/bin/Xvfb", ":" + std::to_string(number),
                                  "-displayfd",    fd,
                                  "-screen",       "0",
                                  "1280x1024x24",  "-nolisten",
                                  "tcp",           "-noreset"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addclose(&fa, fds[0]);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
    pid_t pid = 0;
    const int rc = posix_spawn(&pid, args[0].c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    close(fds[1]);
    if (rc != 0) {
      close(fds[0]);
      throw std::runtime_error("cannot start /usr/bin/Xvfb (apt-get install xvfb)");
    }
    std::string reported;
    char c = 0;
    while (read(fds[0], &c, 1) == 1 && c != '\n') reported += c;
    close(fds[0]);
    if (reported != std::to_string(number) || !accepts_connection(":" + reported)) {
      ::kill(pid, SIGTERM);
      waitpid(pid, nullptr, 0);
      return false;
    }
    pid_ = pid;
    display_ = ":" + reported;
    setenv("DISPLAY", display_.c_str(), 1);
    return true;
  }
};

inline std::filesystem::path brain_scene() { return source_dir() / "scenes/brain_artery.scene"; }

inline std::vector<std::string> server_args(const std::string& prefix, double duration_s) {
  return {(bin_dir() / "neurosim-server").string(),
          "--scene",
          brain_scene().string(),
          "--topic-prefix",
          prefix,
          "--duration",
          std::to_string(duration_s),
          "--cache-dir",
          shared_cache_dir().string()};
}

// Where the tests press the brain: the brain surface vertex furthest right (+x) near the
// scene's load box centre (y 0.115 m, z 0.079 m), and its outward normal.
struct PressPoint {
  Eigen::Vector3d point_m, normal;
};
inline PressPoint press_point(const viewer::MeshState& brain) {
  int best = -1;
  for (const auto& t : brain.surface)
    for (int v : t) {
      const Eigen::Vector3d& p = brain.rest_m[static_cast<std::size_t>(v)];
      if (std::abs(p.y() - 0.115) < 0.006 && std::abs(p.z() - 0.079) < 0.006 &&
          (best < 0 || p.x() > brain.rest_m[static_cast<std::size_t>(best)].x()))
        best = v;
    }
  if (best < 0) throw std::runtime_error("no brain surface vertex near the load box");
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (const auto& t : brain.surface)
    if (t[0] == best || t[1] == best || t[2] == best) {
      const auto& a = brain.rest_m[static_cast<std::size_t>(t[0])];
      const auto& b = brain.rest_m[static_cast<std::size_t>(t[1])];
      const auto& c = brain.rest_m[static_cast<std::size_t>(t[2])];
      n += (b - a).cross(c - a);  // outward (CCW) triangles
    }
  return {brain.rest_m[static_cast<std::size_t>(best)], n.normalized()};
}

}  // namespace neurosim::testing
