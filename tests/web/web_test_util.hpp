// Helpers of the web observer tests: small meshes and displacements, a fake server that publishes
// the topics the bridge reads (MeshTopology, Deformation, ContactModel, SimStatus), neurosim-web
// as a child process, plain HTTP requests, WebSocket clients (CivetWeb's client) that record
// what they get, and a client that never reads.
#pragma once

#include "common/clock.hpp"
#include "common/json.hpp"
#include "idl/wire/dds.hpp"
#include "idl/wire/deformation_codec.hpp"
#include "test_support.hpp"
#include "web/protocol.hpp"

#include <arpa/inet.h>
#include <civetweb.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace neurosim::web::testing {

namespace wire = neurosim::wire;
using neurosim::common::Clock;
using neurosim::common::seconds_since;

inline constexpr const char* kToken = "test-token-0123456789abcdef";

// ---------------------------------------------------------------------------------------------
// Meshes: a strip of 2n vertices (vertex 2i at (i cm, 0, 0), 2i + 1 at (i cm, 1 cm, 0)) and its
// 2 (n - 1) triangles, in scene "test_scene".
inline std::array<double, 3> strip_vertex(std::size_t k) {
  return {0.01 * static_cast<double>(k / 2), 0.01 * static_cast<double>(k % 2), 0.0};
}

struct TestMesh {
  std::unique_ptr<wire::Sample<neurosim_MeshTopology>> topology;
  std::size_t vertices = 0;
};

inline TestMesh strip_mesh(const std::string& id, std::size_t n) {
  TestMesh m;
  m.topology = std::make_unique<wire::Sample<neurosim_MeshTopology>>();
  m.vertices = 2 * n;
  auto& t = **m.topology;
  wire::set_string(t.mesh_id, id, "mesh_id");
  wire::set_string(t.scene_name, "test_scene");
  wire::set_string(t.material_name, "test_material");
  t.youngs_modulus_pa = 3000;
  t.poisson_ratio = 0.45;
  std::vector<double> v;
  for (std::size_t k = 0; k < m.vertices; ++k)
    for (double c : strip_vertex(k)) v.push_back(c);
  std::vector<std::int32_t> tri;
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const auto a = static_cast<std::int32_t>(2 * i);
    tri.insert(tri.end(), {a, a + 2, a + 1, a + 1, a + 2, a + 3});
  }
  wire::assign(t.rest_vertices_m, v);
  wire::assign(t.surface_triangles, tri);
  return m;
}

// A smooth displacement field of the given amplitude (m), 3 per vertex.
inline std::vector<double> displacement(std::size_t vertices, double amplitude_m,
                                        double phase = 0) {
  std::vector<double> u(3 * vertices);
  for (std::size_t i = 0; i < u.size(); ++i)
    u[i] = amplitude_m * std::sin(0.37 * static_cast<double>(i) + phase);
  return u;
}

// ---------------------------------------------------------------------------------------------
// A fake server: one mesh "brain" (a strip of `vertices` vertices), Deformation at frame_hz (the
// real server's codec: FULL every 30 frames, deltas between), ContactModel for station
// "fake-station" at 100 Hz, SimStatus at 1 Hz (liveliness: gone when this object is destroyed).
struct FakeServerOptions {
  std::string topic_prefix;
  int domain = -1;
  std::size_t vertices = 100;  // even
  double frame_hz = 30;        // unit Hz
};

class FakeServer {
 public:
  explicit FakeServer(const FakeServerOptions& o)
      : o_(o),
        pp_(participant_options(o.domain)),
        topo_topic_(pp_, wire::topic_name<neurosim_MeshTopology>(o.topic_prefix)),
        deform_topic_(pp_, wire::topic_name<neurosim_Deformation>(o.topic_prefix)),
        model_topic_(pp_, wire::topic_name<neurosim_ContactModel>(o.topic_prefix)),
        status_topic_(pp_, wire::topic_name<neurosim_SimStatus>(o.topic_prefix)),
        topo_(pp_, topo_topic_),
        deform_(pp_, deform_topic_),
        model_(pp_, model_topic_),
        status_(pp_, status_topic_),
        mesh_(strip_mesh("brain", o.vertices / 2)) {
    topo_.write(**mesh_.topology);
    thread_ = std::thread([this] { run(); });
  }
  ~FakeServer() {
    stop_ = true;
    thread_.join();
  }
  std::uint64_t frames_written() const { return frames_.load(); }
  std::size_t vertices() const { return mesh_.vertices; }
  dds_entity_t participant() const { return pp_.handle(); }

  static wire::ParticipantOptions participant_options(int domain) {
    wire::ParticipantOptions p;
    if (domain >= 0) p.domain = static_cast<dds_domainid_t>(domain);
    return p;
  }

 private:
  void run() {
    wire::DeformationEncoder enc("brain", mesh_.vertices, 0, {});
    wire::Sample<neurosim_Deformation> d;
    wire::Sample<neurosim_ContactModel> c;
    wire::Sample<neurosim_SimStatus> s;
    wire::set_string(c->station_id, "fake-station");
    wire::set_string(c->contact_mesh_id, "brain");
    c->x0_orientation[0] = 1;
    wire::set_string(s->server_id, "fake-server");
    wire::set_string(s->scene_name, "test_scene");
    s->tier = neurosim_TIER_LINEAR;
    s->step_rate_target_hz = s->step_rate_measured_hz = 1000;
    s->viewer_rate_hz = o_.frame_hz;
    s->status_rate_hz = 1;
    const auto t0 = Clock::now();
    double next_frame = 0, next_contact = 0, next_status = 0;
    std::uint64_t n = 0;
    while (!stop_) {
      const double t = seconds_since(t0);
      if (t >= next_frame) {
        const auto u = displacement(mesh_.vertices, 0.002, t);
        enc.encode(u.data(), u.size(), n, common::realtime_ns(), *d);
        deform_.write(*d);
        ++n;
        frames_.store(n);
        next_frame += 1.0 / o_.frame_hz;
      }
      if (t >= next_contact) {
        c->in_contact = true;
        c->f0_n[0] = 0.2 + 0.1 * std::sin(t);
        c->x0_position_m[0] = 0.01;
        c->server_time_ns = common::realtime_ns();
        model_.write(*c);
        next_contact += 0.01;
      }
      if (t >= next_status) {
        s->uptime_s = t;
        s->server_time_ns = common::realtime_ns();
        status_.write(*s);
        next_status += 1.0;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  FakeServerOptions o_;
  wire::Participant pp_;
  wire::Topic<neurosim_MeshTopology> topo_topic_;
  wire::Topic<neurosim_Deformation> deform_topic_;
  wire::Topic<neurosim_ContactModel> model_topic_;
  wire::Topic<neurosim_SimStatus> status_topic_;
  wire::Writer<neurosim_MeshTopology> topo_;
  wire::Writer<neurosim_Deformation> deform_;
  wire::Writer<neurosim_ContactModel> model_;
  wire::Writer<neurosim_SimStatus> status_;
  TestMesh mesh_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> frames_{0};
  std::thread thread_;
};

// ---------------------------------------------------------------------------------------------
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
  bool running() {
    if (pid_ <= 0) return false;
    if (waitpid(pid_, &status_, WNOHANG) == pid_) {
      pid_ = 0;
      return false;
    }
    return true;
  }
  // Waits up to timeout_s for the process to end by itself.
  bool wait(double timeout_s) {
    const auto t0 = Clock::now();
    while (running()) {
      if (seconds_since(t0) > timeout_s) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return true;
  }
  int status() const { return status_; }
  pid_t pid() const { return pid_; }
  std::string log() const { return neurosim::testing::slurp(log_); }
  // Waits until the log contains `text`; returns the log then ("" on timeout).
  std::string wait_for_log(const std::string& text, double timeout_s) {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      std::string l = log();
      if (l.find(text) != std::string::npos) return l;
      if (!running()) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return {};
  }

 private:
  std::filesystem::path log_;
  pid_t pid_ = 0;
  int status_ = -1;
};

// neurosim-web on a free loopback port (bounded by --duration).
class BridgeProcess {
 public:
  BridgeProcess(const std::string& topic_prefix, std::vector<std::string> extra,
                const std::filesystem::path& log, double duration_s = 120) {
    std::vector<std::string> args{(neurosim::testing::bin_dir() / "neurosim-web").string(),
                                  "--listen",
                                  "127.0.0.1:0",
                                  "--token",
                                  kToken,
                                  "--topic-prefix",
                                  topic_prefix,
                                  "--duration",
                                  std::to_string(duration_s)};
    args.insert(args.end(), extra.begin(), extra.end());
    child_ = std::make_unique<Child>(args, log);
    const std::string l = child_->wait_for_log("listening on http://127.0.0.1:", 20);
    const auto p = l.find("listening on http://127.0.0.1:");
    if (p == std::string::npos)
      throw std::runtime_error("neurosim-web did not start: " + child_->log());
    port_ = std::stoi(l.substr(p + std::strlen("listening on http://127.0.0.1:")));
  }
  int port() const { return port_; }
  Child& child() { return *child_; }

 private:
  std::unique_ptr<Child> child_;
  int port_ = 0;
};

// ---------------------------------------------------------------------------------------------
// A connected TCP socket to 127.0.0.1:port (receive buffer rcvbuf bytes when > 0), receive
// timeout 5 s; -1 on failure.
inline int connect_loopback(int port, int rcvbuf = 0) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  if (rcvbuf > 0) setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
  timeval tv{5, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

struct HttpResponse {
  int status = 0;  // 0: no answer
  std::string head, body;
};

// One request (HTTP/1.1, Connection: close), the whole answer read until the server closes.
inline HttpResponse http_request(int port, const std::string& method, const std::string& target,
                                 const std::string& extra_headers = "") {
  HttpResponse r;
  const int fd = connect_loopback(port);
  if (fd < 0) return r;
  const std::string req = method + " " + target +
                          " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
                          "\r\nConnection: close\r\n" + extra_headers + "\r\n";
  if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size())) {
    ::close(fd);
    return r;
  }
  std::string all;
  char buf[65536];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    all.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  const auto end = all.find("\r\n\r\n");
  if (all.rfind("HTTP/1.", 0) != 0 || end == std::string::npos) return r;
  r.status = std::stoi(all.substr(9, 3));
  r.head = all.substr(0, end);
  r.body = all.substr(end + 4);
  return r;
}

inline std::string upgrade_headers() {
  return "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: "
         "dGhlIHNhbXBsZSBub25jZQ==\r\n"
         "Sec-WebSocket-Version: 13\r\n";
}

// /api/stats of a bridge (with the token); null JSON when it does not answer.
inline common::Json bridge_stats(int port) {
  const HttpResponse r = http_request(port, "GET", std::string("/api/stats?token=") + kToken);
  if (r.status != 200) return common::Json();
  return common::Json::parse(r.body);
}

// A WebSocket client that completes the handshake and then never reads: its socket buffers fill
// up and the bridge's writes to it block.
class StalledClient {
 public:
  explicit StalledClient(int port) {
    fd_ = connect_loopback(port, 4096);
    if (fd_ < 0) throw std::runtime_error("StalledClient: cannot connect");
    const std::string req = std::string("GET /ws?token=") + kToken +
                            " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + upgrade_headers() + "\r\n";
    ::send(fd_, req.data(), req.size(), MSG_NOSIGNAL);
  }
  ~StalledClient() { ::close(fd_); }

 private:
  int fd_ = -1;
};

// ---------------------------------------------------------------------------------------------
// A WebSocket client (CivetWeb's client API) recording every message it gets.
class WsClient {
 public:
  struct Received {
    bool binary = false;
    std::string bytes;
    std::int64_t received_ns = 0;  // CLOCK_REALTIME at arrival, unit ns
  };

  explicit WsClient(int port, const std::string& token = kToken) {
    static std::once_flag init;
    std::call_once(init, [] { mg_init_library(0); });
    char err[256] = "";
    const std::string path = "/ws?token=" + token;
    conn_ = mg_connect_websocket_client("127.0.0.1", port, 0, err, sizeof err, path.c_str(),
                                        nullptr, &WsClient::on_data, &WsClient::on_close, this);
    if (conn_ == nullptr) error_ = err;
  }
  ~WsClient() {
    if (conn_ != nullptr) mg_close_connection(conn_);
  }
  WsClient(const WsClient&) = delete;
  WsClient& operator=(const WsClient&) = delete;

  bool connected() const { return conn_ != nullptr; }
  const std::string& error() const { return error_; }
  bool closed_by_server() const { return closed_.load(); }
  std::vector<Received> messages() const {
    std::lock_guard<std::mutex> lk(m_);
    return messages_;
  }
  std::size_t count() const {
    std::lock_guard<std::mutex> lk(m_);
    return messages_.size();
  }
  // Deformation frames received (kind 2), and the newest JSON text message of a type.
  std::size_t frames() const { return frames_.load(); }
  common::Json last_text(const std::string& type) const {
    std::lock_guard<std::mutex> lk(m_);
    for (auto it = messages_.rbegin(); it != messages_.rend(); ++it)
      if (!it->binary) {
        auto j = common::Json::parse(it->bytes);
        if (j.value("type", "") == type) return j;
      }
    return common::Json();
  }
  // The close frame's status code and reason (0, "" before one came).
  std::pair<int, std::string> close_frame() const {
    std::lock_guard<std::mutex> lk(m_);
    return {close_code_, close_reason_};
  }
  // Keep only counters from now on (long runs).
  void keep_messages(bool keep) { keep_.store(keep); }

  bool wait_until(const std::function<bool()>& pred, double timeout_s) const {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      if (pred()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return pred();
  }

 private:
  static int on_data(mg_connection* conn, int flags, char* data, std::size_t len, void* user) {
    auto* self = static_cast<WsClient*>(user);
    const int op = flags & 0x0f;
    if (op == MG_WEBSOCKET_OPCODE_PING) {  // as a browser does (CivetWeb's client does not)
      mg_websocket_client_write(conn, MG_WEBSOCKET_OPCODE_PONG, data, len);
      return 1;
    }
    std::lock_guard<std::mutex> lk(self->m_);
    if (op == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) {
      if (len >= 2)
        self->close_code_ =
            (static_cast<unsigned char>(data[0]) << 8) | static_cast<unsigned char>(data[1]);
      if (len > 2) self->close_reason_.assign(data + 2, len - 2);
      return 0;
    }
    if (op != MG_WEBSOCKET_OPCODE_TEXT && op != MG_WEBSOCKET_OPCODE_BINARY) return 1;
    const bool binary = op == MG_WEBSOCKET_OPCODE_BINARY;
    if (binary && len >= 1 && static_cast<std::uint8_t>(data[0]) == web::kKindDeformationFrame)
      self->frames_.fetch_add(1);
    if (self->keep_.load() || !binary)
      self->messages_.push_back({binary, std::string(data, len), common::realtime_ns()});
    return 1;
  }
  static void on_close(const mg_connection*, void* user) {
    static_cast<WsClient*>(user)->closed_.store(true);
  }

  mg_connection* conn_ = nullptr;
  std::string error_;
  mutable std::mutex m_;
  std::vector<Received> messages_;
  std::atomic<std::size_t> frames_{0};
  std::atomic<bool> closed_{false};
  std::atomic<bool> keep_{true};
  int close_code_ = 0;
  std::string close_reason_;
};

// A topic prefix of its own per test (parallel ctest runs never meet).
inline std::string unique_prefix(const std::string& tag) {
  std::random_device rd;
  return "web" + tag + std::to_string(getpid()) + "_" + std::to_string(rd() % 100000) + "_";
}

}  // namespace neurosim::web::testing
