#include "web/dds_source.hpp"

#include "common/clock.hpp"
#include "idl/wire/client.hpp"
#include "idl/wire/dds.hpp"

#include <atomic>
#include <functional>
#include <cstdlib>
#include <mutex>
#include <string>
#include <thread>

namespace neurosim::web {

namespace {
constexpr dds_attach_t kData = 1;

// Deformation is keep-last 1 on the wire; the bridge's reader keeps a few frames per mesh so a
// FULL frame is not overwritten by the next delta between two takes (history need not match).
wire::Qos deformation_reader_qos() {
  wire::Qos q = wire::reader_qos(wire::Profile::Deformation);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 8);
  return q;
}

// The observer's receive buffers: Cyclone fills each receive thread's buffer (Sizing/
// ReceiveBufferSize, 1 MiB by default) front to back and only then takes a fresh one, so a
// thread that receives little (the discovery port: a few kB a second) touches a new page of its
// buffer every few seconds for a quarter of an hour. That was the observer's slow RSS growth
// (bench/RESULTS.md "client_soak"); with 256 KiB the growth ends where it is flat.
constexpr const char* kReceiveBuffers =
    "<Sizing><ReceiveBufferSize>256KiB</ReceiveBufferSize></Sizing>";

// The observer's DDS domain: the CYCLONEDDS_URI configuration plus kReceiveBuffers, created
// before the session's participant (which then joins it). Not created when CYCLONEDDS_URI is
// unset (the session refuses to start and says why) or when this process has the domain
// already (tests that run a server in the same process): then that domain's configuration holds,
// with its own receive buffers, and the observer says so once.
class ObserverDomain {
 public:
  ObserverDomain(int domain, const std::function<void(const std::string&)>& log) {
    const char* uri = std::getenv("CYCLONEDDS_URI");
    if (uri == nullptr || *uri == '\0') return;
    const std::string config = std::string(uri) + "," + kReceiveBuffers;
    // DDS_DOMAIN_DEFAULT is not allowed here: the configurations' <Domain id="any"> serve id 0,
    // the default.
    const dds_entity_t d = dds_create_domain(domain < 0 ? 0 : domain, config.c_str());
    if (d > 0) {
      handle_ = d;
    } else if (d == DDS_RETCODE_PRECONDITION_NOT_MET) {
      log("neurosim-web: DDS domain " + std::to_string(domain < 0 ? 0 : domain) +
          " already exists in this process: the observer uses its configuration (not the " +
          "observer's 256 KiB receive buffers)");
    }
  }
  ~ObserverDomain() {
    if (handle_ > 0) dds_delete(handle_);
  }
  ObserverDomain(const ObserverDomain&) = delete;
  ObserverDomain& operator=(const ObserverDomain&) = delete;
  bool created() const { return handle_ > 0; }

 private:
  dds_entity_t handle_ = 0;
};

}  // namespace

struct DdsSource::Impl {
  Hub& hub;
  Log log;
  const double stations_period_s;
  ObserverDomain domain;  // before the session: its participant joins this domain
  // The shared client set-up (participant, prefixed topics, the server's SimStatus and its
  // liveliness on the waitset) plus the observer's own readers.
  wire::ClientSession session;
  wire::Topic<neurosim_MeshTopology> topo_topic;
  wire::Topic<neurosim_Deformation> deform_topic;
  wire::Topic<neurosim_ContactModel> model_topic;
  wire::Reader<neurosim_MeshTopology> topologies;
  wire::Reader<neurosim_Deformation> deformations;
  wire::Reader<neurosim_ContactModel> models;
  wire::Reader<neurosim_SimStatus>& status;
  wire::Waitset& ws;
  ObserverState state;  // DDS thread only
  mutable std::mutex counters_m;
  ObserverCounters counters_copy;
  std::atomic<bool> alive{false};
  std::atomic<bool> stop{false};
  std::thread thread;

  Impl(const DdsSourceOptions& o, Hub& h, Log l)
      : hub(h),
        log(std::move(l)),
        stations_period_s(o.stations_hz > 0 ? 1.0 / o.stations_hz : 1.0 / 30),
        domain(o.domain, log),
        session(wire::ClientOptions{o.domain, o.topic_prefix}),
        topo_topic(session.topic<neurosim_MeshTopology>()),
        deform_topic(session.topic<neurosim_Deformation>()),
        model_topic(session.topic<neurosim_ContactModel>()),
        topologies(session.participant(), topo_topic),
        deformations(session.participant(), deform_topic, deformation_reader_qos(), wire::ReaderOptions{64}),
        models(session.participant(), model_topic),
        status(session.status()),
        ws(session.waitset()),
        state([this](const std::string& m) { log("neurosim-web: " + m); }) {
    ws.attach_data(topologies, kData);
    ws.attach_data(deformations, kData);
    // ContactModel arrives at 1 kHz per station: it is taken at stations_hz (keep-last 1 per
    // station: the newest waits in the reader), not attached to the waitset.
  }

  void run();
};

void DdsSource::Impl::run() {
  using common::Clock;
  using common::seconds_since;
  auto last_stations = Clock::now(), rate_window = Clock::now(), last_status = Clock::now();
  std::uint64_t frames_in_window = 0;
  double deformation_hz = 0;
  bool stations_dirty = false;
  const auto period = static_cast<dds_duration_t>(stations_period_s * 1e9);
  while (!stop.load()) {
    ws.wait(period);
    if (stop.load()) break;
    bool status_dirty = false;

    // Server liveliness first: a restarted server's topology then lands in a live state.
    if (state.set_server_alive(session.server_alive())) {
      alive.store(state.server_alive());
      log(state.server_alive() ? "neurosim-web: server seen (SimStatus writer alive)"
                               : "neurosim-web: server gone (SimStatus writer lost); the "
                                 "clients keep the last state");
      status_dirty = true;
    }
    for (;;) {
      const auto batch = status.take();
      if (batch.empty()) break;
      for (const auto& rx : batch)
        if (rx.valid()) status_dirty |= state.ingest_status(rx.data);
    }
    // Topologies before frames: a frame needs its mesh.
    for (;;) {
      const auto batch = topologies.take();
      if (batch.empty()) break;
      for (const auto& rx : batch) {
        if (!rx.valid()) continue;
        if (TopologyPtr t = state.ingest_topology(rx.data)) {
          log("neurosim-web: mesh '" + std::string(rx.data.mesh_id) + "' (" +
              std::to_string(wire::view(rx.data.rest_vertices_m).size / 3) + " vertices, " +
              std::to_string(wire::view(rx.data.surface_triangles).size / 3) +
              " surface triangles): topology generation " + std::to_string(t->generation));
          hub.publish_topology(std::move(t));
        }
      }
    }
    for (;;) {
      const auto batch = deformations.take();
      if (batch.empty()) break;
      for (const auto& rx : batch) {
        if (!rx.valid()) continue;
        if (FramePtr f = state.ingest_deformation(rx.data)) {
          ++frames_in_window;
          hub.publish_frame(std::move(f));
        }
      }
    }
    for (;;) {
      const auto batch = models.take();
      if (batch.empty()) break;
      for (const auto& rx : batch) {
        if (rx.valid())
          stations_dirty |= state.ingest_contact(rx.data);
        else if (rx.disposed())
          stations_dirty |= state.remove_station(rx.key());
      }
    }
    if (stations_dirty && seconds_since(last_stations) >= stations_period_s) {
      hub.publish_stations(state.stations_message());
      last_stations = Clock::now();
      stations_dirty = false;
    }
    const double window_s = seconds_since(rate_window);
    if (window_s >= 1.0) {
      // Per mesh: every mesh has its own frames at the server's viewer rate.
      const TopologyPtr t = state.topology();
      const double meshes = t && t->meshes > 0 ? static_cast<double>(t->meshes) : 1.0;
      deformation_hz = static_cast<double>(frames_in_window) / window_s / meshes;
      frames_in_window = 0;
      rate_window = Clock::now();
    }
    if (status_dirty || seconds_since(last_status) >= 1.0) {
      BridgeRates r;
      r.deformation_hz = deformation_hz;
      r.clients = hub.clients();
      r.max_clients = hub.max_clients();
      hub.publish_status(state.status_message(r));
      last_status = Clock::now();
    }
    std::lock_guard<std::mutex> lk(counters_m);
    counters_copy = state.counters();
  }
}

DdsSource::DdsSource(const DdsSourceOptions& options, Hub& hub, Log log)
    : impl_(std::make_unique<Impl>(options, hub, std::move(log))) {
  impl_->thread = std::thread([this] { impl_->run(); });
}

DdsSource::~DdsSource() {
  impl_->stop.store(true);
  impl_->ws.wake();
  if (impl_->thread.joinable()) impl_->thread.join();
}

ObserverCounters DdsSource::counters() const {
  std::lock_guard<std::mutex> lk(impl_->counters_m);
  return impl_->counters_copy;
}

bool DdsSource::server_alive() const { return impl_->alive.load(); }

}  // namespace neurosim::web
