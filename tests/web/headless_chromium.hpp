// Debian's Chromium, headless, driven through its DevTools protocol over a pipe
// (--remote-debugging-pipe: commands on fd 3, answers and events on fd 4, one JSON message per
// NUL-terminated chunk), so no debugging port is opened. Loopback only: every host name but
// 127.0.0.1 resolves to nothing and the background services are off. WebGL renders in software
// (SwiftShader).
#pragma once

#include "common/clock.hpp"
#include "common/json.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

extern char** environ;

namespace neurosim::web::testing {

class HeadlessChromium {
 public:
  HeadlessChromium(const std::string& executable, const std::filesystem::path& profile_dir,
                   const std::filesystem::path& log, int width, int height)
      : width_(width), height_(height) {
    int to_browser[2], from_browser[2];
    if (pipe2(to_browser, O_CLOEXEC) != 0 || pipe2(from_browser, O_CLOEXEC) != 0)
      throw std::runtime_error("pipe failed");
    // The child's ends above 4 first, so that moving them to 3 and 4 cannot clobber each other.
    const int child_in = fcntl(to_browser[0], F_DUPFD_CLOEXEC, 10);
    const int child_out = fcntl(from_browser[1], F_DUPFD_CLOEXEC, 10);
    close(to_browser[0]);
    close(from_browser[1]);
    std::vector<std::string> args{
        executable,
        "--headless",
        "--remote-debugging-pipe",
        "--no-sandbox",  // the tests may run as root
        "--user-data-dir=" + profile_dir.string(),
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-default-apps",
        "--disable-extensions",
        "--disable-domain-reliability",
        "--disable-client-side-phishing-detection",
        "--disable-features=Translate,OptimizationHints,MediaRouter,AutofillServerCommunication",
        "--metrics-recording-only",
        "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--hide-scrollbars",
        "--mute-audio",
        "--window-size=" + std::to_string(width) + "," + std::to_string(height),
        "about:blank"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    posix_spawn_file_actions_adddup2(&fa, child_in, 3);
    posix_spawn_file_actions_adddup2(&fa, child_out, 4);
    const int rc = posix_spawn(&pid_, executable.c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    close(child_in);
    close(child_out);
    out_ = to_browser[1];
    in_ = from_browser[0];
    if (rc != 0) throw std::runtime_error("cannot start " + executable);
  }
  ~HeadlessChromium() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      const auto t0 = common::Clock::now();
      while (waitpid(pid_, nullptr, WNOHANG) == 0) {
        if (common::seconds_since(t0) > 5) {
          ::kill(pid_, SIGKILL);
          waitpid(pid_, nullptr, 0);
          break;
        }
        usleep(20000);
      }
    }
    close(out_);
    close(in_);
  }
  HeadlessChromium(const HeadlessChromium&) = delete;
  HeadlessChromium& operator=(const HeadlessChromium&) = delete;

  // Sends a command and waits for its answer's "result"; throws on an error answer or timeout.
  common::Json call(const std::string& method, const common::Json& params = common::Json::object(),
                    const std::string& session = "", double timeout_s = 20) {
    const int id = ++next_id_;
    common::Json msg{{"id", id}, {"method", method}, {"params", params}};
    if (!session.empty()) msg["sessionId"] = session;
    std::string text = msg.dump();
    text.push_back('\0');
    for (std::size_t done = 0; done < text.size();) {
      const ssize_t n = ::write(out_, text.data() + done, text.size() - done);
      if (n <= 0) throw std::runtime_error("Chromium: cannot send " + method);
      done += static_cast<std::size_t>(n);
    }
    const auto t0 = common::Clock::now();
    for (;;) {
      const double left = timeout_s - common::seconds_since(t0);
      if (left <= 0) throw std::runtime_error("Chromium: no answer to " + method);
      common::Json m = next_message(left);
      if (m.is_null()) continue;
      if (m.contains("id") && m["id"] == id) {
        if (m.contains("error"))
          throw std::runtime_error("Chromium: " + method + ": " + m["error"].dump());
        return m["result"];
      }
      if (m.value("method", "") == "Runtime.exceptionThrown")
        exceptions_.push_back(m["params"]["exceptionDetails"].dump());
    }
  }

  // A new tab showing url; returns its session id. Runtime events (exceptions) are recorded.
  std::string open(const std::string& url) {
    const std::string target = call("Target.createTarget", {{"url", "about:blank"}})["targetId"];
    const std::string session =
        call("Target.attachToTarget", {{"targetId", target}, {"flatten", true}})["sessionId"];
    call("Emulation.setDeviceMetricsOverride",
         {{"width", width_}, {"height", height_}, {"deviceScaleFactor", 1}, {"mobile", false}},
         session);
    call("Runtime.enable", common::Json::object(), session);
    call("Page.navigate", {{"url", url}}, session);
    return session;
  }

  // The value of a JavaScript expression in the page (promises awaited); throws when it throws.
  common::Json evaluate(const std::string& session, const std::string& expression,
                        double timeout_s = 20) {
    const common::Json r =
        call("Runtime.evaluate",
             {{"expression", expression}, {"returnByValue", true}, {"awaitPromise", true}}, session,
             timeout_s);
    if (r.contains("exceptionDetails"))
      throw std::runtime_error("page: " + expression.substr(0, 80) + ": " +
                               r["exceptionDetails"].dump());
    return r["result"].value("value", common::Json());
  }

  // PNG of a region of the page (CSS pixels), base64.
  std::string screenshot(const std::string& session, double x, double y, double w, double h) {
    return call("Page.captureScreenshot",
                {{"format", "png"},
                 {"clip", {{"x", x}, {"y", y}, {"width", w}, {"height", h}, {"scale", 1}}}},
                session)["data"];
  }

  const std::vector<std::string>& exceptions() const { return exceptions_; }

 private:
  // The next message, or null JSON when none came within timeout_s.
  common::Json next_message(double timeout_s) {
    for (;;) {
      const auto nul = buf_.find('\0');
      if (nul != std::string::npos) {
        std::string one = buf_.substr(0, nul);
        buf_.erase(0, nul + 1);
        return common::Json::parse(one);
      }
      pollfd p{in_, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(timeout_s * 1000)) <= 0) return common::Json();
      char chunk[65536];
      const ssize_t n = ::read(in_, chunk, sizeof chunk);
      if (n <= 0) throw std::runtime_error("Chromium closed its DevTools pipe (it exited)");
      buf_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  int width_, height_;
  pid_t pid_ = 0;
  int out_ = -1, in_ = -1;
  int next_id_ = 0;
  std::string buf_;
  std::vector<std::string> exceptions_;
};

// Decodes base64 (the screenshots, to keep them as files).
inline std::string base64_decode(const std::string& in) {
  static const std::string chars =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int val = 0, bits = -8;
  for (char c : in) {
    const auto p = chars.find(c);
    if (p == std::string::npos) break;  // '=' padding ends it
    val = (val << 6) + static_cast<int>(p);
    bits += 6;
    if (bits >= 0) {
      out.push_back(static_cast<char>((val >> bits) & 0xff));
      bits -= 8;
    }
  }
  return out;
}

}  // namespace neurosim::web::testing
