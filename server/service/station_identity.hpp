// Station identity (docs/ARCHITECTURE.md "Station identity"): which station id a ToolState
// writer may write. A writer publishes in the DDS partition "neurosim.station.<id>" of ONE
// station (idl/wire/qos.hpp); its claim is read from discovery (matched publication data) once
// and cached per writer. The cache is shared with a Cyclone topic filter that drops a cached
// writer's samples for any other id before they reach the reader's history, so a stranger
// cycling through ids cannot grow the reader's instance table (memory bounded by the number of
// writers, not of ids).
#pragma once

#include "idl/wire/dds.hpp"

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace neurosim::service {

using Guid = std::array<std::uint8_t, 16>;

// The station a writer in these partitions claims: the id of its one "neurosim.station.<id>"
// partition (no wildcard characters, a valid id). None for no such partition, or several.
std::optional<std::string> station_claim(const std::vector<std::string>& partitions);

struct WriterInfo {
  std::string claim;       // "" : no valid claim (every sample rejected, cause identity)
  Guid guid{};
  Guid participant{};
};

class WriterClaims {
 public:
  explicit WriterClaims(std::size_t max_writers = 256) : max_writers_(max_writers) {}
  // Cached info of a writer, or nullopt.
  std::optional<WriterInfo> find(dds_instance_handle_t writer) const;
  // Caches a writer; false if the cache is full (the caller purges, or rejects the sample).
  bool insert(dds_instance_handle_t writer, const WriterInfo& info);
  void erase(dds_instance_handle_t writer);
  std::vector<dds_instance_handle_t> writers() const;
  std::size_t size() const;
  // Samples the topic filter dropped (claim mismatch), since start.
  std::uint64_t filtered() const { return filtered_.load(std::memory_order_relaxed); }
  // Installs the filter on a topic (before its reader is created). The topic must be used by
  // the server's ToolState reader only; this object must outlive the topic.
  void install_filter(dds_entity_t topic);

 private:
  static bool filter(const void* sample, const dds_sample_info_t* info, void* arg);
  std::size_t max_writers_;
  mutable std::mutex m_;
  std::unordered_map<dds_instance_handle_t, WriterInfo> writers_;
  std::atomic<std::uint64_t> filtered_{0};
};

}  // namespace neurosim::service
