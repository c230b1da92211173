// QoS profiles of every neurosim topic, in ONE place (docs/ARCHITECTURE.md "DDS").
//
//   topic          reliability  durability       history     liveliness (writer)  autodispose
//   ToolState      best effort  volatile         keep-last 1 automatic 500 ms     on
//   ContactModel   reliable     volatile         keep-last 1 automatic 500 ms     on
//   Deformation    best effort  volatile         keep-last 1 (default)            on
//   MeshTopology   reliable     transient-local  keep-last 1 (default)            on
//   SimStatus      reliable     transient-local  keep-last 1 automatic 500 ms     OFF
//
// History is per instance (key), so keep-last 1 means the newest sample of each station/mesh.
// Readers request the default (infinite) liveliness lease, which matches any writer's offer.
// No deadline QoS anywhere: after a missed deadline Cyclone 0.10.2 stops reporting writer loss
// through instance state (docs/ARCHITECTURE.md "DDS"); death is detected with
// liveliness_changed instead.
#pragma once

#include "idl/wire/types.hpp"

#include <dds/dds.h>

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
Qos writer_qos(Profile p);
Qos reader_qos(Profile p);
const char* to_string(Profile p);

}  // namespace neurosim::wire
