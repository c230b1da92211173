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

bool WriterClaims::insert(dds_instance_handle_t writer, const WriterInfo& info) {
  std::lock_guard<std::mutex> lk(m_);
  if (writers_.size() >= max_writers_ && writers_.count(writer) == 0) return false;
  writers_[writer] = info;
  return true;
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
