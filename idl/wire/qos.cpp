#include "idl/wire/qos.hpp"

#include <stdexcept>
#include <utility>

namespace neurosim::wire {

Qos::Qos() : q_(dds_create_qos()) {
  if (q_ == nullptr) throw std::runtime_error("DDS: dds_create_qos returned null");
}
Qos::~Qos() {
  if (q_ != nullptr) dds_delete_qos(q_);
}
Qos::Qos(const Qos& o) : Qos() { dds_copy_qos(q_, o.q_); }
Qos& Qos::operator=(const Qos& o) {
  if (this != &o) dds_copy_qos(q_, o.q_);
  return *this;
}
Qos::Qos(Qos&& o) noexcept : q_(std::exchange(o.q_, nullptr)) {}
Qos& Qos::operator=(Qos&& o) noexcept {
  std::swap(q_, o.q_);
  return *this;
}

const char* to_string(Profile p) {
  switch (p) {
    case Profile::ToolState: return "tool_state";
    case Profile::ContactModel: return "contact_model";
    case Profile::Deformation: return "deformation";
    case Profile::MeshTopology: return "mesh_topology";
    case Profile::SimStatus: return "sim_status";
  }
  return "unknown";
}

namespace {

// What writer and reader of a topic share (these must match for the two to communicate).
void common(dds_qos_t* q, Profile p) {
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
  switch (p) {
    case Profile::ToolState:
    case Profile::Deformation:
      // Only the newest pose / frame matters; a lost one is replaced by the next (1 kHz / 30 Hz).
      dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
      dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
      break;
    case Profile::ContactModel:
      // The haptic loop must not miss the model that answers its pose; keep-last 1 never blocks.
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(10));
      dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
      break;
    case Profile::MeshTopology:
    case Profile::SimStatus:
      // Late joiners (viewers, a remote trainer) get the last sample per key.
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
      dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
      break;
  }
}

}  // namespace

Qos topic_qos(Profile p) {
  Qos q;
  common(q.get(), p);
  return q;
}

namespace {

void set_liveliness_and_lifecycle(dds_qos_t* q, Profile p) {
  switch (p) {
    case Profile::ToolState:
    case Profile::ContactModel:
      // A killed station / server shows as not alive within the lease, not the 10 s default.
      dds_qset_liveliness(q, DDS_LIVELINESS_AUTOMATIC, kLivelinessLease);
      break;
    case Profile::SimStatus:
      // Server death → liveliness_changed; the last status stays readable (no autodispose).
      dds_qset_liveliness(q, DDS_LIVELINESS_AUTOMATIC, kLivelinessLease);
      dds_qset_writer_data_lifecycle(q, false);
      break;
    case Profile::Deformation:
    case Profile::MeshTopology:
      break;
  }
}

}  // namespace

Qos writer_qos(Profile p) {
  if (p == Profile::ToolState)
    throw std::logic_error(
        "ToolState writer without a station: its QoS is tool_state_writer_qos(station_id) (the "
        "station's partition, idl/wire/qos.hpp)");
  Qos q;
  common(q.get(), p);
  set_liveliness_and_lifecycle(q.get(), p);
  return q;
}

Qos reader_qos(Profile p) {
  Qos q;
  common(q.get(), p);
  if (p == Profile::ToolState) {
    const char* parts[] = {kToolStateReaderPartition};
    dds_qset_partition(q.get(), 1, parts);
  }
  return q;
}

std::string station_partition(std::string_view station_id) {
  if (station_id.empty()) throw std::invalid_argument("station partition: empty station id");
  if (station_id.size() > neurosim_ID_MAX)
    throw std::invalid_argument("station partition: station id '" + std::string(station_id) +
                                "' is longer than " + std::to_string(neurosim_ID_MAX) +
                                " characters");
  if (station_id.find_first_of("*?[]\\") != std::string_view::npos)
    throw std::invalid_argument("station partition: station id '" + std::string(station_id) +
                                "' has a partition wildcard character (* ? [ ] \\)");
  return kStationPartitionPrefix + std::string(station_id);
}

Qos tool_state_writer_qos(std::string_view station_id) {
  const std::string part = station_partition(station_id);
  Qos q;
  common(q.get(), Profile::ToolState);
  set_liveliness_and_lifecycle(q.get(), Profile::ToolState);
  const char* parts[] = {part.c_str()};
  dds_qset_partition(q.get(), 1, parts);
  return q;
}

std::vector<std::string> partitions_of(const dds_qos_t* qos) {
  std::vector<std::string> out;
  uint32_t n = 0;
  char** ps = nullptr;
  if (qos == nullptr || !dds_qget_partition(qos, &n, &ps)) return out;
  for (uint32_t i = 0; i < n; ++i) {
    out.emplace_back(ps[i] ? ps[i] : "");
    dds_free(ps[i]);
  }
  dds_free(ps);
  return out;
}

}  // namespace neurosim::wire
