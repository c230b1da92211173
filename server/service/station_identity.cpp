#include "server/service/station_identity.hpp"

#include <cstring>
#include <stdexcept>

namespace neurosim::service {

std::optional<std::string> station_claim(const std::vector<std::string>& partitions) {
  const std::string_view prefix = wire::kStationPartitionPrefix;
  std::optional<std::string> claim;
  for (const auto& p : partitions) {
    if (p.size() <= prefix.size() || p.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string id = p.substr(prefix.size());
    if (id.size() > neurosim_ID_MAX || id.find_first_of("*?[]\\") != std::string::npos)
      return std::nullopt;
    if (claim && *claim != id) return std::nullopt;  // a writer speaks for one station only
    claim = id;
  }
  return claim;
}

std::optional<WriterInfo> WriterClaims::find(dds_instance_handle_t writer) const {
  std::lock_guard<std::mutex> lk(m_);
  const auto it = writers_.find(writer);
  if (it == writers_.end()) return std::nullopt;
  return it->second;
}

WriterClaims::WriterClaims(WriterLimits limits) : limits_(limits) {
  if (limits_.max_writers < 1 || limits_.max_per_participant < 1 || limits_.evict_idle_ns < 0)
    throw std::invalid_argument("writer limits: max_writers and max_per_participant must be >= 1, "
                                "evict_idle_ns >= 0");
}

Admitted WriterClaims::admit(dds_instance_handle_t writer, const WriterInfo& info,
                             const std::function<bool(dds_instance_handle_t)>& pinned,
                             dds_instance_handle_t* evicted) {
  if (evicted != nullptr) *evicted = 0;
  std::lock_guard<std::mutex> lk(m_);
  if (const auto it = writers_.find(writer); it != writers_.end()) {
    it->second = info;
    return Admitted::kCached;
  }
  // The writer idle longest among those `eligible` accepts (pinned writers never).
  const auto idlest = [&](const auto& eligible) {
    auto best = writers_.end();
    for (auto it = writers_.begin(); it != writers_.end(); ++it) {
      if (!eligible(it->second) || (pinned && pinned(it->first))) continue;
      if (best == writers_.end() || it->second.last_seen_mono_ns < best->second.last_seen_mono_ns) best = it;
    }
    return best;
  };
  Admitted result = Admitted::kCached;
  std::size_t own = 0;
  for (const auto& [h, w] : writers_)
    if (w.participant == info.participant) ++own;
  if (own >= limits_.max_per_participant) {
    // One participant never holds more: its own idlest writer makes room.
    const auto victim = idlest([&](const WriterInfo& w) { return w.participant == info.participant; });
    if (victim == writers_.end()) return Admitted::kFull;
    if (evicted != nullptr) *evicted = victim->first;
    writers_.erase(victim);
    result = Admitted::kEvictedOwn;
  } else if (writers_.size() >= limits_.max_writers) {
    const std::int64_t now = info.last_seen_mono_ns;
    const auto victim = idlest([&](const WriterInfo& w) { return now - w.last_seen_mono_ns >= limits_.evict_idle_ns; });
    if (victim == writers_.end()) return Admitted::kFull;
    if (evicted != nullptr) *evicted = victim->first;
    writers_.erase(victim);
    result = Admitted::kEvictedIdle;
  }
  writers_[writer] = info;
  return result;
}

void WriterClaims::touch(dds_instance_handle_t writer, std::int64_t now_mono_ns) {
  std::lock_guard<std::mutex> lk(m_);
  const auto it = writers_.find(writer);
  if (it != writers_.end()) it->second.last_seen_mono_ns = now_mono_ns;
}

std::size_t WriterClaims::count_of(const Guid& participant) const {
  std::lock_guard<std::mutex> lk(m_);
  std::size_t n = 0;
  for (const auto& [h, w] : writers_)
    if (w.participant == participant) ++n;
  return n;
}

void WriterClaims::erase(dds_instance_handle_t writer) {
  std::lock_guard<std::mutex> lk(m_);
  writers_.erase(writer);
}

std::vector<dds_instance_handle_t> WriterClaims::writers() const {
  std::lock_guard<std::mutex> lk(m_);
  std::vector<dds_instance_handle_t> out;
  out.reserve(writers_.size());
  for (const auto& [h, info] : writers_) out.push_back(h);
  return out;
}

std::size_t WriterClaims::size() const {
  std::lock_guard<std::mutex> lk(m_);
  return writers_.size();
}

// Runs on Cyclone's receive thread for every ToolState sample of the server's reader: only a
// map look-up under a mutex no one holds across a DDS call.
bool WriterClaims::filter(const void* sample, const dds_sample_info_t* info, void* arg) {
  auto* self = static_cast<WriterClaims*>(arg);
  if (info == nullptr || info->publication_handle == 0) return true;
  const auto* s = static_cast<const neurosim_ToolState*>(sample);
  std::lock_guard<std::mutex> lk(self->m_);
  const auto it = self->writers_.find(info->publication_handle);
  if (it == self->writers_.end()) return true;  // unknown yet: the DDS thread looks it up
  if (std::strncmp(it->second.claim.c_str(), s->station_id, neurosim_ID_MAX + 1) == 0) return true;
  self->filtered_.fetch_add(1, std::memory_order_relaxed);
  return false;
}

void WriterClaims::install_filter(dds_entity_t topic) {
  dds_topic_filter f{};
  f.mode = DDS_TOPIC_FILTER_SAMPLE_SAMPLEINFO_ARG;
  f.f.sample_sampleinfo_arg = &WriterClaims::filter;
  f.arg = this;
  wire::check(dds_set_topic_filter_extended(topic, &f), "set ToolState topic filter (station identity)");
}

}  // namespace neurosim::service
