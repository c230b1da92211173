#include "viewer_client/viewer/dds_client.hpp"

#include "idl/wire/client.hpp"
#include "idl/wire/dds.hpp"

#include <optional>

namespace neurosim::viewer {

namespace {
constexpr dds_attach_t kData = 1;

// Deformation is keep-last 1 on the wire, but the viewer renders slower than the 30 Hz stream:
// its reader keeps the last second of frames so the FULL frames that the deltas refer to are
// never overwritten between two polls (reader history need not match the writer's).
wire::Qos deformation_reader_qos() {
  wire::Qos q = wire::reader_qos(wire::Profile::Deformation);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 64);
  return q;
}
}  // namespace

// The shared client set-up (wire::ClientSession: participant, prefixed topics, the server's
// SimStatus and its liveliness on the waitset) plus the viewer's own readers.
struct DdsClient::Impl {
  wire::ClientSession session;
  wire::Topic<neurosim_MeshTopology> topo_topic;
  wire::Topic<neurosim_Deformation> deform_topic;
  wire::Topic<neurosim_ToolState> tool_topic;
  wire::Topic<neurosim_ContactModel> model_topic;
  wire::Reader<neurosim_MeshTopology> topologies;
  wire::Reader<neurosim_Deformation> deformations;
  wire::Reader<neurosim_ToolState> tools;
  wire::Reader<neurosim_ContactModel> models;
  wire::Reader<neurosim_SimStatus>& status;
  wire::Waitset& ws;

  explicit Impl(const DdsClientOptions& o)
      : session(wire::ClientOptions{o.domain, o.topic_prefix}),
        topo_topic(session.topic<neurosim_MeshTopology>()),
        deform_topic(session.topic<neurosim_Deformation>()),
        tool_topic(session.topic<neurosim_ToolState>()),
        model_topic(session.topic<neurosim_ContactModel>()),
        topologies(session.participant(), topo_topic),
        deformations(session.participant(), deform_topic, deformation_reader_qos(), wire::ReaderOptions{128}),
        tools(session.participant(), tool_topic),
        models(session.participant(), model_topic),
        status(session.status()),
        ws(session.waitset()) {
    ws.attach_data(topologies, kData);
    ws.attach_data(deformations, kData);
  }
};

DdsClient::DdsClient(const DdsClientOptions& options) : impl_(std::make_unique<Impl>(options)) {}
DdsClient::~DdsClient() = default;

void DdsClient::wait(double timeout_s) {
  impl_->ws.wait(static_cast<dds_duration_t>(timeout_s * 1e9));
}

bool DdsClient::poll(ViewerState& state) {
  Impl& im = *impl_;
  bool changed = false;
  // Server liveliness first: a restarted server's topology then lands in a "live" state.
  const bool alive = im.session.server_alive();
  if (alive != state.server_alive()) {
    state.set_server_alive(alive);
    changed = true;
  }
  // Every status is taken (the reader must stay empty so the waitset idles); the newest valid
  // one is shown (tier, equilibrium rate).
  for (;;) {
    const auto batch = im.status.take();
    if (batch.empty()) break;
    for (const auto& rx : batch)
      if (rx.valid()) changed |= state.ingest_status(rx.data);
  }

  // Topologies before deformations: a frame needs its mesh.
  for (;;) {
    const auto batch = im.topologies.take();
    if (batch.empty()) break;
    for (const auto& rx : batch)
      if (rx.valid()) changed |= state.ingest_topology(rx.data);
  }
  for (;;) {
    const auto batch = im.deformations.take();
    if (batch.empty()) break;
    for (const auto& rx : batch)
      if (rx.valid()) changed |= state.ingest_deformation(rx.data);
  }
  for (;;) {
    const auto batch = im.tools.take();
    if (batch.empty()) break;
    for (const auto& rx : batch) {
      if (rx.valid())
        changed |= state.ingest_tool(rx.data);
      else if (rx.disposed() || rx.no_writers()) {
        state.remove_station(std::string(rx.key()));
        changed = true;
      }
    }
  }
  for (;;) {
    const auto batch = im.models.take();
    if (batch.empty()) break;
    for (const auto& rx : batch)
      if (rx.valid()) changed |= state.ingest_contact(rx.data);
  }
  return changed;
}

}  // namespace neurosim::viewer
