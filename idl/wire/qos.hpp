// QoS profiles of every neurosim topic, in ONE place (docs/ARCHITECTURE.md "DDS").
//
//   topic          reliability  durability       history     liveliness (writer)  autodispose
//   ToolState      best effort  volatile         keep-last 1 automatic 500 ms     on
//   ContactModel   reliable     volatile         keep-last 1 automatic 500 ms     on
//   Deformation    best effort  volatile         keep-last 1 (default)            on
//   MeshTopology   reliable     transient-local  keep-last 1 (default)            on
//   SimStatus      reliable     transient-local  keep-last 1 automatic 500 ms     OFF
//
// Partitions (the station identity contract, docs/ARCHITECTURE.md "Station identity"): a
// ToolState writer publishes in "neurosim.station.<station_id>" of its one station
// (tool_state_writer_qos), ToolState readers subscribe to "neurosim.station.*"; every other topic
// stays in the default partition. DDS Security permissions (deploy/secure) build on this.
//
// History is per instance (key), so keep-last 1 means the newest sample of each station/mesh.
// Readers request the default (infinite) liveliness lease, which matches any writer's offer.
// No deadline QoS anywhere: after a missed deadline Cyclone 0.10.2 stops reporting writer loss
// through instance state (docs/ARCHITECTURE.md "DDS"); death is detected with
// liveliness_changed instead.
#pragma once

#include "idl/wire/types.hpp"

#include <dds/dds.h>

#include <string>
#include <string_view>
#include <vector>

namespace neurosim::wire {

// Lease of the writers with automatic liveliness: readers see a dead writer ~this long after.
inline constexpr dds_duration_t kLivelinessLease = DDS_MSECS(500);

// Owns a dds_qos_t.
class Qos {
 public:
  Qos();
  ~Qos();
  Qos(const Qos& o);
  Qos& operator=(const Qos& o);
  Qos(Qos&& o) noexcept;
  Qos& operator=(Qos&& o) noexcept;
  dds_qos_t* get() const { return q_; }

 private:
  dds_qos_t* q_;
};

Qos topic_qos(Profile p);
// Profile::ToolState is refused (std::logic_error): a ToolState writer needs its station's
// partition, tool_state_writer_qos(station_id).
Qos writer_qos(Profile p);
// Profile::ToolState: in kToolStateReaderPartition (every station's partition).
Qos reader_qos(Profile p);

// The partition prefix of the stations and the readers' wildcard over it.
inline constexpr const char* kStationPartitionPrefix = "neurosim.station.";
inline constexpr const char* kToolStateReaderPartition = "neurosim.station.*";
// "neurosim.station." + station_id. Throws std::invalid_argument for an empty id, one longer than
// neurosim_ID_MAX or one with a partition wildcard character (* ? [ ] \\).
std::string station_partition(std::string_view station_id);
// The QoS of the writer of station_id's ToolState: writer_qos's settings in its partition.
Qos tool_state_writer_qos(std::string_view station_id);
// The partitions in a QoS (empty: the default partition).
std::vector<std::string> partitions_of(const dds_qos_t* qos);
const char* to_string(Profile p);

}  // namespace neurosim::wire
