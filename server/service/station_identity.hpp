// Station identity (docs/ARCHITECTURE.md "Station identity"): which station id a ToolState
// writer may write. A writer publishes in the DDS partition "neurosim.station.<id>" of ONE
// station (idl/wire/qos.hpp); its claim is read from discovery (matched publication data) once
// and cached per writer. The cache is shared with a Cyclone topic filter that drops a cached
// writer's samples for any other id before they reach the reader's history, so a stranger
// cycling through ids cannot grow the reader's instance table (memory bounded by the number of
// writers, not of ids). The cache is bounded in total and per participant: one participant's
// writers (300 idle ones, say) evict each other, never another participant's, and a full cache
// evicts the writer idle longest before it turns a newcomer away.
#pragma once

#include "idl/wire/dds.hpp"

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
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
  std::int64_t last_seen_mono_ns{0};  // newest sample of this writer (monotonic clock), unit ns
};

struct WriterLimits {
  std::size_t max_writers{256};         // writers cached at once (>= 1)
  std::size_t max_per_participant{8};   // of one DDS participant (>= 1)
  // A full cache evicts the writer idle longest, if it has been idle at least this long, unit ns.
  std::int64_t evict_idle_ns{1000000000};
};

// What admit() did.
enum class Admitted {
  kCached,            // in the cache (it was, or there was room)
  kEvictedOwn,        // its participant was at its limit: that participant's writer idle longest left
  kEvictedIdle,       // the cache was full: the writer idle longest (another participant's) left
  kFull,              // not cached: the cache is full of writers that are pinned or recently active
};

class WriterClaims {
 public:
  explicit WriterClaims(WriterLimits limits = {});
  // Cached info of a writer, or nullopt.
  std::optional<WriterInfo> find(dds_instance_handle_t writer) const;
  // Caches a writer (info.last_seen_mono_ns: now). A pinned writer (bound to an active station)
  // is never evicted. *evicted (if not null) gets the writer that left, else 0.
  Admitted admit(dds_instance_handle_t writer, const WriterInfo& info,
                 const std::function<bool(dds_instance_handle_t)>& pinned,
                 dds_instance_handle_t* evicted = nullptr);
  // A sample of a cached writer arrived at now_mono_ns.
  void touch(dds_instance_handle_t writer, std::int64_t now_mono_ns);
  void erase(dds_instance_handle_t writer);
  std::vector<dds_instance_handle_t> writers() const;
  std::size_t size() const;
  // Cached writers of one participant.
  std::size_t count_of(const Guid& participant) const;
  const WriterLimits& limits() const { return limits_; }
  // Samples the topic filter dropped (claim mismatch), since start.
  std::uint64_t filtered() const { return filtered_.load(std::memory_order_relaxed); }
  // Installs the filter on a topic (before its reader is created). The topic must be used by
  // the server's ToolState reader only; this object must outlive the topic.
  void install_filter(dds_entity_t topic);

 private:
  static bool filter(const void* sample, const dds_sample_info_t* info, void* arg);
  WriterLimits limits_;
  mutable std::mutex m_;
  std::unordered_map<dds_instance_handle_t, WriterInfo> writers_;
  std::atomic<std::uint64_t> filtered_{0};
};

}  // namespace neurosim::service
