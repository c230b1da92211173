// Helpers for the service tests: a server child process (bounded, killed on scope exit), a DDS
// client on the server's private domain, scripted tool poses.
#pragma once

#include "common/clock.hpp"
#include "idl/wire/dds.hpp"
#include "test_support.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <array>
#include <atomic>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::service::testing {

namespace wire = neurosim::wire;
using neurosim::common::Clock;
using neurosim::common::seconds_since;

// A DDS domain of its own per test run, so parallel tests and other people's processes on the
// loopback never see each other's samples.
inline int private_domain() {
  // Reserved, not only drawn: two tests running at once once drew the same domain and each
  // server answered the other test's station (same station ids). Domains 20..219 are tried from
  // a random start; each is taken with an exclusive lock on a file in the temporary directory,
  // kept (the descriptor stays open, closed on exec) until this process exits, so no other test
  // process gets it meanwhile; a second call in one process gets another domain.
  std::random_device rd;
  const int start = static_cast<int>(rd() % 200);
  for (int k = 0; k < 200; ++k) {
    const int d = 20 + (start + k) % 200;
    const std::string path =
        (std::filesystem::temp_directory_path() / ("neurosim_dds_domain_" + std::to_string(d) + ".lock")).string();
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) return d;
    ::close(fd);
  }
  throw std::runtime_error("private_domain: every test DDS domain (20-219) is held by another process");
}

// A child process (fork + execv), stdout/stderr to a log file. Killed (SIGKILL) if still alive
// when destroyed.
class ChildProcess {
 public:
  ChildProcess(const std::filesystem::path& exe, const std::vector<std::string>& args,
               const std::filesystem::path& log_file)
      : log_(log_file) {
    std::vector<std::string> all{exe.string()};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int fd = ::open(log_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_ = ::fork();
    if (pid_ == 0) {
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    if (fd >= 0) ::close(fd);
    if (pid_ < 0) throw std::runtime_error("fork failed");
  }
  ~ChildProcess() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      int st = 0;
      ::waitpid(pid_, &st, 0);
    }
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  bool alive() {
    if (exited_) return false;
    int st = 0;
    const pid_t r = ::waitpid(pid_, &st, WNOHANG);
    if (r == pid_) {
      exited_ = true;
      status_ = st;
    }
    return !exited_;
  }
  // Sends sig and waits up to timeout_s; returns the exit code (or 128 + signal), -1 on timeout
  // (then the process is killed).
  int signal_and_wait(int sig, double timeout_s) {
    if (alive()) ::kill(pid_, sig);
    return wait(timeout_s);
  }
  int wait(double timeout_s) {
    const auto t0 = Clock::now();
    while (alive() && seconds_since(t0) < timeout_s) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (alive()) {
      ::kill(pid_, SIGKILL);
      int st = 0;
      ::waitpid(pid_, &st, 0);
      exited_ = true;
      return -1;
    }
    if (WIFEXITED(status_)) return WEXITSTATUS(status_);
    if (WIFSIGNALED(status_)) return 128 + WTERMSIG(status_);
    return -2;
  }
  std::string log() const {
    return neurosim::testing::slurp(log_);
  }

 private:
  std::filesystem::path log_;
  pid_t pid_{-1};
  bool exited_{false};
  int status_{0};
};

// What a client of the server needs: a participant on the server's domain, typed endpoints.
struct Client {
  explicit Client(int domain) : pp(options(domain)) {}
  static wire::ParticipantOptions options(int domain) {
    wire::ParticipantOptions o;
    o.domain = static_cast<dds_domainid_t>(domain);
    return o;
  }
  wire::Participant pp;
  wire::Topic<neurosim_ToolState> tool_topic{pp};
  wire::Topic<neurosim_ContactModel> model_topic{pp};
  wire::Topic<neurosim_SimStatus> status_topic{pp};
  wire::Topic<neurosim_MeshTopology> topo_topic{pp};
  wire::Topic<neurosim_Deformation> deform_topic{pp};
};

// Scripted tool sample: station id, tool, position, identity orientation, now as source time.
inline void fill_tool(neurosim_ToolState& s, const char* station, std::uint64_t seq,
                      const double p[3], std::int64_t time_ns) {
  wire::set_string(s.station_id, station, "station_id");
  wire::set_string(s.tool_id, "probe", "tool_id");
  for (int i = 0; i < 3; ++i) {
    s.position_m[i] = p[i];
    s.velocity_m_per_s[i] = 0;
  }
  s.orientation[0] = 1;
  s.orientation[1] = s.orientation[2] = s.orientation[3] = 0;
  s.buttons = 0;
  s.sequence_number = seq;
  s.source_time_ns = time_ns;
}

// |a - b| <= rel * max(|b|, floor), componentwise on n values.
inline ::testing::AssertionResult near_rel(const double* a, const double* b, int n, double rel,
                                           double floor) {
  for (int i = 0; i < n; ++i) {
    const double tol = rel * std::max(std::abs(b[i]), floor);
    if (!(std::abs(a[i] - b[i]) <= tol))
      return ::testing::AssertionFailure()
             << "component " << i << ": " << a[i] << " vs " << b[i] << " (tol " << tol << ")";
  }
  return ::testing::AssertionSuccess();
}

}  // namespace neurosim::service::testing

namespace neurosim::service::testing {

// One received ContactModel (copied out of the reader).
struct ModelRecord {
  std::string station;
  std::uint64_t tool_sequence{0};
  bool in_contact{false};
  bool rejected{false};
  double f0[3]{}, K[9]{}, normal[3]{}, x0[3]{};
  std::uint64_t server_step{0};
  std::string mesh;
  int rigid_planes{0};                 // the proxy's constraint planes (rigid obstacles)
  double rigid_penetration_m{0.0};     // deepest raw penetration behind them, unit m
};

// Takes ContactModels on its own thread (the reader keeps only the newest per station, so it
// must be taken promptly) and records them, and which stations were disposed.
class ModelCollector {
 public:
  explicit ModelCollector(Client& c) : reader_(c.pp, c.model_topic), ws_(c.pp) {
    ws_.attach_data(reader_, 1);
    thread_ = std::thread([this] { loop(); });
  }
  ~ModelCollector() {
    run_ = false;
    ws_.wake();
    thread_.join();
  }
  std::vector<ModelRecord> records() {
    std::lock_guard<std::mutex> lk(m_);
    return recs_;
  }
  std::size_t count(const std::string& station) {
    std::lock_guard<std::mutex> lk(m_);
    std::size_t n = 0;
    for (const auto& r : recs_) n += r.station == station;
    return n;
  }
  // The tool_sequence of the newest ContactModel received for `station` (0: none).
  std::uint64_t newest_sequence(const std::string& station) {
    std::lock_guard<std::mutex> lk(m_);
    for (auto it = recs_.rbegin(); it != recs_.rend(); ++it)
      if (it->station == station) return it->tool_sequence;
    return 0;
  }
  bool disposed(const std::string& station) {
    std::lock_guard<std::mutex> lk(m_);
    for (const auto& s : disposed_) if (s == station) return true;
    return false;
  }
  bool wait_for(const std::function<bool()>& pred, double timeout_s) {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      if (pred()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return pred();
  }

 private:
  void loop() {
    while (run_) {
      ws_.wait(DDS_MSECS(50));
      const auto b = reader_.take();
      std::lock_guard<std::mutex> lk(m_);
      for (const auto& rx : b) {
        if (rx.disposed() || rx.no_writers()) disposed_.emplace_back(rx.key());
        if (!rx.valid()) continue;
        const auto& d = rx.data;
        ModelRecord r;
        r.station = d.station_id;
        r.tool_sequence = d.tool_sequence;
        r.in_contact = d.in_contact;
        r.rejected = d.tool_sample_rejected;
        for (int i = 0; i < 3; ++i) {
          r.f0[i] = d.f0_n[i];
          r.normal[i] = d.normal[i];
          r.x0[i] = d.x0_position_m[i];
        }
        for (int i = 0; i < 9; ++i) r.K[i] = d.stiffness_n_per_m[i];
        r.server_step = d.server_step;
        r.mesh = d.contact_mesh_id;
        r.rigid_planes = static_cast<int>(d.rigid_planes._length);
        for (std::uint32_t j = 0; j < d.rigid_planes._length; ++j)
          r.rigid_penetration_m = std::max(r.rigid_penetration_m, d.rigid_planes._buffer[j].penetration_m);
        recs_.push_back(r);
      }
    }
  }
  wire::Reader<neurosim_ContactModel> reader_;
  wire::Waitset ws_;
  std::atomic<bool> run_{true};
  std::mutex m_;
  std::vector<ModelRecord> recs_;
  std::vector<std::string> disposed_;
  std::thread thread_;
};

// Newest SimStatus of the server (transient-local: a new reader gets the last one).
class StatusWatcher {
 public:
  explicit StatusWatcher(Client& c) : reader_(c.pp, c.status_topic), ws_(c.pp) { ws_.attach_data(reader_, 1); }
  // Waits until pred(status) holds for a received status; returns whether it did.
  bool wait_for(const std::function<bool(const neurosim_SimStatus&)>& pred, double timeout_s) {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      const auto b = reader_.take();
      for (const auto& rx : b) {
        // A dispose while a sample is unread marks that sample instead of adding an invalid one.
        if (rx.disposed()) server_disposed = true;
        if (!rx.valid()) continue;
        last_steps = rx.data.steps;
        last_text = describe(rx.data);
        if (pred(rx.data)) return true;
      }
      ws_.wait(DDS_MSECS(50));
    }
    return false;
  }
  bool server_disposed{false};
  std::uint64_t last_steps{0};
  std::string last_text;  // the newest status, for failure messages

  static std::string describe(const neurosim_SimStatus& s) {
    std::ostringstream os;
    os << "SimStatus steps " << s.steps << " rate " << s.step_rate_measured_hz << " Hz p50 " << s.step_time_p50_us
       << " us p99 " << s.step_time_p99_us << " us, rejected non-finite " << s.samples_rejected_nonfinite
       << " jump " << s.samples_rejected_jump << " workspace " << s.samples_rejected_workspace << " time "
       << s.samples_rejected_time << " sequence " << s.samples_rejected_sequence << " identity "
       << s.samples_rejected_identity << " rate " << s.samples_rejected_rate << ", refused " << s.stations_refused
       << ", reclaimed " << s.stations_reclaimed << ", log lines suppressed " << s.log_lines_suppressed
       << ", stations:";
    for (const auto& st : wire::view(s.stations))
      os << " [" << st.station_id << " accepted " << st.samples_accepted << " nonfinite "
         << st.samples_rejected_nonfinite << " jump " << st.samples_rejected_jump << " last " << st.last_sequence
         << (st.in_contact ? " contact" : "") << "]";
    return os.str();
  }

 private:
  wire::Reader<neurosim_SimStatus> reader_;
  wire::Waitset ws_;
};

inline const neurosim_StationStatus* find_station(const neurosim_SimStatus& s, const std::string& id) {
  for (const auto& st : wire::view(s.stations))
    if (id == st.station_id) return &st;
  return nullptr;
}

// Writes ToolState for one station at 1 kHz (absolute deadlines) on its own thread; pose(t_s)
// gives the position, t_s counted from the first sample. Remembers every position sent, by
// sequence number. The first sample waits for the server's reader to be matched (at most 30 s):
// a sample written before that reaches nobody, and a server slow to load on a loaded machine
// would otherwise see little or none of a short run (a 4 s run once saw no model at all).
class StationThread {
 public:
  // hold_every = k > 0: every k-th sample is held back and written right after the next one, as a
  // network that reorders packets would deliver them.
  StationThread(Client& c, std::string id, std::function<std::array<double, 3>(double)> pose,
                double seconds, std::uint64_t hold_every = 0)
      : writer_(c.pp, c.tool_topic, id), id_(std::move(id)), pose_(std::move(pose)), seconds_(seconds),
        hold_every_(hold_every) {
    thread_ = std::thread([this] { loop(); });
  }
  ~StationThread() { join(); }
  void join() {
    run_ = false;
    if (thread_.joinable()) thread_.join();
  }
  void wait_done() {
    if (thread_.joinable()) thread_.join();
  }
  // Position sent with sequence number seq (1-based).
  std::array<double, 3> sent(std::uint64_t seq) {
    std::lock_guard<std::mutex> lk(m_);
    return sent_.at(seq - 1);
  }
  std::uint64_t sent_count() {
    std::lock_guard<std::mutex> lk(m_);
    return sent_.size();
  }
  const wire::Writer<neurosim_ToolState>& writer() const { return writer_; }

 private:
  void loop() {
    wire::Sample<neurosim_ToolState> s, held;
    bool holding = false;
    for (int i = 0; i < 300 && run_ && !writer_.wait_for_readers(1, DDS_MSECS(100)); ++i) {
    }
    std::int64_t next = neurosim::common::monotonic_ns();
    const auto t0 = Clock::now();
    std::uint64_t seq = 0;
    while (run_ && seconds_since(t0) < seconds_) {
      const auto p = pose_(seconds_since(t0));
      {
        std::lock_guard<std::mutex> lk(m_);
        sent_.push_back(p);
      }
      ++seq;
      if (hold_every_ > 0 && seq % hold_every_ == 0) {
        fill_tool(*held, id_.c_str(), seq, p.data(), dds_time());
        holding = true;
      } else {
        fill_tool(*s, id_.c_str(), seq, p.data(), dds_time());
        writer_.write(*s);
        if (holding) writer_.write(*held);
        holding = false;
      }
      next += 1000000;
      neurosim::common::sleep_until_ns(next);
    }
  }
  wire::Writer<neurosim_ToolState> writer_;
  std::string id_;
  std::function<std::array<double, 3>(double)> pose_;
  double seconds_;
  std::uint64_t hold_every_;
  std::atomic<bool> run_{true};
  std::mutex m_;
  std::vector<std::array<double, 3>> sent_;
  std::thread thread_;
};

}  // namespace neurosim::service::testing
