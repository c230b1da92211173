// web_bench: what the web observer costs and delivers, on loopback.
//   - bytes per deformation frame for the brain/artery scene: FULL (float32) and QUANTIZED_DELTA
//     (int16), as the bridge sends them, and the topology a client gets once;
//   - frames per second delivered to 1 and 10 WebSocket clients, at the server's viewer rate
//     (30 Hz) and with the publisher as fast as it goes (1 kHz asked);
//   - latency from a Deformation sample (stamped as it is written) to its WebSocket message
//     arriving at a client, p50/p99/max.
// neurosim-web runs as a child process (the program itself, beside this one); this process
// publishes the brain and artery meshes of scenes/brain_artery/ with a moving dent through the
// server's codec (idl/wire/deformation_codec) and runs the clients (CivetWeb's client).
//
//   web_bench [--seconds S] [--csv]
#include "common/cli.hpp"
#include "common/process_stats.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "idl/wire/dds.hpp"
#include "idl/wire/deformation_codec.hpp"
#include "server/mesh/io.hpp"
#include "web/protocol.hpp"

#include <civetweb.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>
#include <thread>
#include <vector>

extern char** environ;
namespace wire = neurosim::wire;
namespace web = neurosim::web;
namespace fs = std::filesystem;
using neurosim::common::Clock;
using neurosim::common::realtime_ns;
using neurosim::common::seconds_since;

namespace {

constexpr const char* kToken = "web-bench-token-0123456789";

struct MeshDef {
  std::string id;
  std::vector<double> rest_m;
  std::vector<std::int32_t> triangles;
  std::size_t vertices() const { return rest_m.size() / 3; }
};

MeshDef load(const std::string& id, const fs::path& file) {
  const auto d = neurosim::mesh::read_medit(file.string(), 0.001);
  MeshDef m;
  m.id = id;
  for (const auto& v : d.vertices_m) m.rest_m.insert(m.rest_m.end(), {v[0], v[1], v[2]});
  for (const auto& t : d.triangles)
    m.triangles.insert(m.triangles.end(),
                       {static_cast<std::int32_t>(t[0]), static_cast<std::int32_t>(t[1]),
                        static_cast<std::int32_t>(t[2])});
  return m;
}

// A dent of depth 5 mm and radius 15 mm around a surface point, moving along a circle.
void dent(const MeshDef& m, double t, std::vector<double>& u) {
  u.assign(m.rest_m.size(), 0.0);
  const double cx = 0.16 + 0.01 * std::cos(t), cy = 0.1125 + 0.01 * std::sin(t), cz = 0.0787;
  for (std::size_t i = 0; i < m.vertices(); ++i) {
    const double dx = m.rest_m[3 * i] - cx, dy = m.rest_m[3 * i + 1] - cy,
                 dz = m.rest_m[3 * i + 2] - cz;
    const double w = std::exp(-(dx * dx + dy * dy + dz * dz) / (2 * 0.015 * 0.015));
    u[3 * i] = -0.005 * w;
  }
}

// Publishes the meshes (MeshTopology once) and their Deformation at `rate_hz` (0: paused), plus a
// SimStatus so the bridge sees a live server.
class Publisher {
 public:
  Publisher(const std::string& prefix, std::vector<MeshDef> meshes)
      : meshes_(std::move(meshes)),
        topo_topic_(pp_, wire::topic_name<neurosim_MeshTopology>(prefix)),
        deform_topic_(pp_, wire::topic_name<neurosim_Deformation>(prefix)),
        status_topic_(pp_, wire::topic_name<neurosim_SimStatus>(prefix)),
        topo_(pp_, topo_topic_),
        deform_(pp_, deform_topic_),
        status_(pp_, status_topic_) {
    for (const MeshDef& m : meshes_) {
      wire::Sample<neurosim_MeshTopology> t;
      wire::set_string(t->mesh_id, m.id, "mesh_id");
      wire::set_string(t->scene_name, "brain_artery");
      wire::assign(t->rest_vertices_m, m.rest_m);
      wire::assign(t->surface_triangles, m.triangles);
      topo_.write(*t);
    }
    wire::Sample<neurosim_SimStatus> s;
    wire::set_string(s->server_id, "web_bench");
    wire::set_string(s->scene_name, "brain_artery");
    s->tier = neurosim_TIER_LINEAR;
    status_.write(*s);
    thread_ = std::thread([this] { run(); });
  }
  ~Publisher() {
    stop_ = true;
    thread_.join();
  }
  void set_rate(double hz) { rate_hz_.store(hz); }
  std::uint64_t written() const { return written_.load(); }

 private:
  void run() {
    std::vector<std::unique_ptr<wire::DeformationEncoder>> enc;
    for (const MeshDef& m : meshes_)
      enc.push_back(std::make_unique<wire::DeformationEncoder>(m.id, m.vertices(), 0));
    wire::Sample<neurosim_Deformation> d;
    std::vector<double> u;
    std::uint64_t step = 0;
    double next = seconds_since(t0_);
    while (!stop_) {
      const double hz = rate_hz_.load();
      if (hz <= 0) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        next = seconds_since(t0_);
        continue;
      }
      const double t = seconds_since(t0_);
      if (t < next) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        continue;
      }
      next += 1.0 / hz;
      if (next < t) next = t;  // behind (the codec or DDS is slower than asked): no backlog
      ++step;
      for (std::size_t k = 0; k < meshes_.size(); ++k) {
        dent(meshes_[k], t, u);
        // Stamped just before the write: the latency covers DDS, the bridge and the WebSocket.
        enc[k]->encode(u.data(), u.size(), step, 0, *d);
        d->server_time_ns = realtime_ns();
        deform_.write(*d);
        written_.fetch_add(1);
      }
    }
  }

  std::vector<MeshDef> meshes_;
  wire::Participant pp_;
  wire::Topic<neurosim_MeshTopology> topo_topic_;
  wire::Topic<neurosim_Deformation> deform_topic_;
  wire::Topic<neurosim_SimStatus> status_topic_;
  wire::Writer<neurosim_MeshTopology> topo_;
  wire::Writer<neurosim_Deformation> deform_;
  wire::Writer<neurosim_SimStatus> status_;
  const Clock::time_point t0_ = Clock::now();
  std::atomic<double> rate_hz_{0};
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> written_{0};
  std::thread thread_;
};

// A WebSocket client counting frames and their latency (arrival - server_time_ns).
class Client {
 public:
  explicit Client(int port) {
    char err[256] = "";
    const std::string path = std::string("/ws?token=") + kToken;
    conn_ = mg_connect_websocket_client("127.0.0.1", port, 0, err, sizeof err, path.c_str(),
                                        nullptr, &Client::on_data, nullptr, this);
    if (conn_ == nullptr) throw std::runtime_error(std::string("web_bench: client: ") + err);
  }
  ~Client() { mg_close_connection(conn_); }
  void reset() {
    std::lock_guard<std::mutex> lk(m_);
    frames_ = 0;
    latency_ms_.clear();
  }
  std::uint64_t frames() const {
    std::lock_guard<std::mutex> lk(m_);
    return frames_;
  }
  std::vector<double> latencies_ms() const {
    std::lock_guard<std::mutex> lk(m_);
    return latency_ms_;
  }

 private:
  static int on_data(mg_connection* conn, int flags, char* data, std::size_t len, void* user) {
    const std::int64_t now = realtime_ns();
    auto* self = static_cast<Client*>(user);
    if ((flags & 0x0f) == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
    if ((flags & 0x0f) == MG_WEBSOCKET_OPCODE_PING) {  // as a browser does
      mg_websocket_client_write(conn, MG_WEBSOCKET_OPCODE_PONG, data, len);
      return 1;
    }
    if ((flags & 0x0f) != MG_WEBSOCKET_OPCODE_BINARY || len < web::kFrameHeaderBytes ||
        static_cast<std::uint8_t>(data[0]) != web::kKindDeformationFrame)
      return 1;
    const web::FrameHeader h = web::parse_frame_header(data, len);
    std::lock_guard<std::mutex> lk(self->m_);
    ++self->frames_;
    if (self->latency_ms_.size() < 2000000)
      self->latency_ms_.push_back(1e-6 * static_cast<double>(now - h.server_time_ns));
    return 1;
  }
  mg_connection* conn_ = nullptr;
  mutable std::mutex m_;
  std::uint64_t frames_ = 0;
  std::vector<double> latency_ms_;
};

// neurosim-web beside this program, on a free loopback port; killed at the end.
class BridgeChild {
 public:
  BridgeChild(const std::string& prefix, const fs::path& log) {
    const fs::path exe = fs::read_symlink("/proc/self/exe").parent_path() / "neurosim-web";
    std::vector<std::string> args{exe.string(), "--listen",       "127.0.0.1:0", "--token",
                                  kToken,       "--topic-prefix", prefix,        "--max-clients",
                                  "16",         "--duration",     "600"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (posix_spawn(&pid_, exe.c_str(), &fa, nullptr, argv.data(), environ) != 0)
      throw std::runtime_error("web_bench: cannot start " + exe.string());
    posix_spawn_file_actions_destroy(&fa);
    const auto t0 = Clock::now();
    const std::string key = "listening on http://127.0.0.1:";
    while (seconds_since(t0) < 20) {
      std::ifstream in(log);
      const std::string text((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
      const auto p = text.find(key);
      if (p != std::string::npos) {
        port_ = std::stoi(text.substr(p + key.size()));
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    throw std::runtime_error("web_bench: neurosim-web did not start (see " + log.string() + ")");
  }
  ~BridgeChild() {
    kill(pid_, SIGINT);
    waitpid(pid_, nullptr, 0);
  }
  int port() const { return port_; }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = 0;
  int port_ = 0;
};


}  // namespace

int main(int argc, char** argv) {
  double seconds = 5;
  bool csv = false;
  neurosim::cli::Parser cli("web_bench",
                            "Web observer: bytes per frame, frames/s to 1 and 10 "
                            "WebSocket clients, Deformation-to-WebSocket latency.");
  cli.add_option("--seconds", seconds, "measurement per case, unit s")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_flag("--csv", csv, "CSV instead of a table");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    std::cerr << "web_bench: set CYCLONEDDS_URI (deploy/cyclonedds/loopback.xml)\n";
    return 1;
  }
  signal(SIGPIPE, SIG_IGN);
  mg_init_library(0);
  try {
    const fs::path scene_dir = fs::path(NEUROSIM_SOURCE_DIR) / "scenes/brain_artery";
    std::vector<MeshDef> meshes{load("artery", scene_dir / "artery.mesh"),
                                load("brain", scene_dir / "brain.mesh")};

    // Bytes per frame, as the bridge sends them (the server's codec, this header).
    std::printf(csv ? "mesh,vertices,surface_triangles,full_bytes,delta_bytes,geometry_bytes\n"
                    : "%-8s %9s %9s %11s %11s %14s\n",
                "mesh", "vertices", "triangles", "full_B", "delta_B", "geometry_B");
    for (const MeshDef& m : meshes) {
      wire::DeformationEncoder enc(m.id, m.vertices(), 0);
      wire::Sample<neurosim_Deformation> d;
      std::vector<double> u;
      dent(m, 0, u);
      enc.encode(u.data(), u.size(), 0, 0, *d);
      const std::size_t full = web::frame_message(*d, 0, 1).bytes.size();
      dent(m, 0.1, u);
      enc.encode(u.data(), u.size(), 1, 0, *d);
      const std::size_t delta = web::frame_message(*d, 0, 1).bytes.size();
      std::vector<float> rest(m.rest_m.begin(), m.rest_m.end());
      std::vector<std::uint32_t> tri(m.triangles.begin(), m.triangles.end());
      const std::size_t geometry = web::geometry_message(0, 1, rest, tri).bytes.size();
      std::printf(csv ? "%s,%zu,%zu,%zu,%zu,%zu\n" : "%-8s %9zu %9zu %11zu %11zu %14zu\n",
                  m.id.c_str(), m.vertices(), m.triangles.size() / 3, full, delta, geometry);
    }
    std::printf("\n");

    std::random_device rd;
    const std::string prefix =
        "webbench" + std::to_string(getpid()) + "_" + std::to_string(rd() % 100000) + "_";
    const fs::path log =
        fs::temp_directory_path() / ("web_bench_" + std::to_string(getpid()) + ".log");
    Publisher pub(prefix, meshes);
    BridgeChild bridge(prefix, log);

    std::printf(csv ? "clients,asked_hz,published_hz,delivered_fps_mean,delivered_fps_min,"
                      "latency_p50_ms,latency_p99_ms,latency_max_ms,bridge_cpu_pct\n"
                    : "%7s %8s %12s %13s %12s %9s %9s %9s %10s\n",
                "clients", "asked_Hz", "published_Hz", "delivered_fps", "min_fps", "p50_ms",
                "p99_ms", "max_ms", "bridge_cpu");
    for (const double hz : {30.0, 1000.0}) {
      for (const int n : {1, 10}) {
        std::vector<std::unique_ptr<Client>> clients;
        for (int i = 0; i < n; ++i) clients.push_back(std::make_unique<Client>(bridge.port()));
        pub.set_rate(hz);
        std::this_thread::sleep_for(std::chrono::seconds(1));  // topology, first keyframes
        for (auto& c : clients) c->reset();
        const std::uint64_t w0 = pub.written();
        const double cpu0 = neurosim::common::cpu_seconds(bridge.pid());
        const auto t0 = Clock::now();
        std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
        const double wall = seconds_since(t0);
        const double cpu = neurosim::common::cpu_seconds(bridge.pid()) - cpu0;
        // Per mesh: frames are counted per mesh message, so divide by the meshes.
        const double published =
            static_cast<double>(pub.written() - w0) / wall / static_cast<double>(meshes.size());
        double sum = 0, min = 1e300;
        std::vector<double> lat;
        for (auto& c : clients) {
          const double fps =
              static_cast<double>(c->frames()) / wall / static_cast<double>(meshes.size());
          sum += fps;
          min = std::min(min, fps);
          const auto l = c->latencies_ms();
          lat.insert(lat.end(), l.begin(), l.end());
        }
        pub.set_rate(0);
        const auto p = neurosim::common::percentiles(lat);
        std::printf(csv ? "%d,%.0f,%.1f,%.1f,%.1f,%.2f,%.2f,%.2f,%.1f\n"
                        : "%7d %8.0f %12.1f %13.1f %12.1f %9.2f %9.2f %9.2f %9.1f%%\n",
                    n, hz, published, sum / n, min, p.p50, p.p99, p.max, 100 * cpu / wall);
        std::fflush(stdout);
        std::vector<std::thread> closers;  // CivetWeb's client joins its thread on close
        for (auto& c : clients) closers.emplace_back([p = c.release()] { delete p; });
        for (auto& t : closers) t.join();
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
      }
    }
    if (!csv)
      std::printf(
          "\n(frames per second per mesh: the brain and the artery each get this many; "
          "latency: Deformation written -> WebSocket message received, both meshes)\n");
  } catch (const std::exception& e) {
    std::cerr << "web_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
