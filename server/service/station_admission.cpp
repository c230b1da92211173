#include "server/service/station_admission.hpp"

#include "common/clock.hpp"
#include "server/model/settings.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace neurosim::service {

namespace {
const double kDefaultMaxSpeed = scene::ToolDef{}.max_speed_m_per_s;  // unit m/s
}  // namespace

void StationAdmissionDef::validate() const {
  if (max_stations < 0)
    throw std::invalid_argument("max_stations " + std::to_string(max_stations) + " is below 0");
  if (!(std::isfinite(station_idle_timeout_s) && station_idle_timeout_s >= 0.05 &&
        station_idle_timeout_s <= 3600))
    throw std::invalid_argument("station idle timeout " + std::to_string(station_idle_timeout_s) +
                                " s is outside [0.05, 3600] s");
  if (max_stations_per_participant < 1)
    throw std::invalid_argument("max stations per participant " +
                                std::to_string(max_stations_per_participant) + " is below 1");
  if (writers.max_per_participant <= static_cast<std::size_t>(max_stations_per_participant))
    throw std::invalid_argument("max writers per participant " +
                                std::to_string(writers.max_per_participant) +
                                " must be above max stations per participant " +
                                std::to_string(max_stations_per_participant) +
                                " (a participant's bound writers are never evicted)");
  if (!(std::isfinite(max_future_s) && max_future_s >= 0))
    throw std::invalid_argument("max future " + std::to_string(max_future_s) + " s is not finite and >= 0");
  if (!(std::isfinite(max_station_rate_hz) && max_station_rate_hz >= 10))
    throw std::invalid_argument("max station rate " + std::to_string(max_station_rate_hz) +
                                " Hz is not finite and >= 10 Hz");
  if (tool_ids.size() != tool_max_speed_m_per_s.size())
    throw std::invalid_argument("tool_ids and tool_max_speed_m_per_s differ in length");
}

StationAdmission::StationAdmission(StationAdmissionDef def, std::function<void(const std::string&)> log,
                                   std::function<void()> on_pose)
    : def_((def.validate(), std::move(def))),
      log_(std::move(log)),
      on_pose_(std::move(on_pose)),
      claims_(def_.writers),
      slots_(static_cast<std::size_t>(def_.max_stations)),
      log_limit_(def_.log_lines_per_second) {
  refusals_.reserve(kMaxRefusals + 1);
}

void StationAdmission::limited_log(const char* cause, const std::string& line) {
  std::string summary;
  const bool ok = log_limit_.allow(cause, common::monotonic_ns(), &summary);
  suppressed_lines_.store(log_limit_.suppressed_total(), std::memory_order_relaxed);
  if (!log_) return;
  if (!summary.empty()) log_(summary);
  if (ok) log_(line);
}

bool StationAdmission::pinned(dds_instance_handle_t writer) const {
  for (const auto& [key, i] : slot_of_station_)
    if (slots_[static_cast<std::size_t>(i)].writer == writer) return true;
  return false;
}

// The writer's claim from the cache, else from discovery (then cached). A writer that cannot be
// cached (the table full of pinned or recently active writers) is refused, with a refusal
// published, so its station hears of it at once instead of being ignored.
StationAdmission::WriterLookup StationAdmission::writer_info(dds_instance_handle_t writer,
                                                             const std::string& key,
                                                             std::int64_t now_mono) {
  WriterLookup r;
  if (auto w = claims_.find(writer)) {
    claims_.touch(writer, now_mono);
    w->last_seen_mono_ns = now_mono;
    r.info = w;
    return r;
  }
  if (directory_ == nullptr) {
    r.why = "no writer directory";
    return r;
  }
  const wire::MatchedPublication mp = directory_->matched(writer);
  if (!mp.matched) {
    r.why = "writer not matched (gone)";
    return r;
  }
  WriterInfo info;
  info.claim = station_claim(mp.partitions).value_or(std::string());
  info.guid = mp.guid;
  info.participant = mp.participant_guid;
  info.last_seen_mono_ns = now_mono;
  const auto is_pinned = [this](dds_instance_handle_t h) { return pinned(h); };
  dds_instance_handle_t evicted = 0;
  Admitted a = claims_.admit(writer, info, is_pinned, &evicted);
  if (a == Admitted::kFull) {
    // Writers that left without our noticing make room first.
    for (const auto h : claims_.writers())
      if (!directory_->matched(h).matched) claims_.erase(h);
    a = claims_.admit(writer, info, is_pinned, &evicted);
  }
  if (a == Admitted::kFull) {
    const WriterLimits& l = claims_.limits();
    refuse(key, info.guid, neurosim_REFUSED_MAX_STATIONS,
           "the server's table of ToolState writers is full (" + std::to_string(l.max_writers) +
               " writers, none idle for " + std::to_string(1e-9 * static_cast<double>(l.evict_idle_ns)) +
               " s); try again later");
    r.refused = true;
    r.why = "writer table full";
    return r;
  }
  if (a == Admitted::kEvictedOwn || a == Admitted::kEvictedIdle) {
    ++counters.writers_evicted;
    if (a == Admitted::kEvictedOwn)
      limited_log("writers", "a participant at its limit of " +
                                 std::to_string(claims_.limits().max_per_participant) +
                                 " ToolState writers opened another (for '" + key +
                                 "'): its writer idle longest was evicted");
    else
      limited_log("writers", "the writer table is full: the writer idle longest was evicted to admit "
                             "one for '" + key + "'");
  }
  r.info = info;
  return r;
}

void StationAdmission::refuse(const std::string& key, const Guid& guid, neurosim_RefusalReason reason,
                              const std::string& why) {
  bool fresh = true;
  const std::int64_t wall = dds_time();
  {
    std::lock_guard<std::mutex> lk(refusal_mutex_);
    auto it = std::find_if(refusals_.begin(), refusals_.end(), [&](const neurosim_StationRefusal& r) {
      return std::memcmp(r.writer_guid, guid.data(), 16) == 0 && key == r.station_id && r.reason == reason;
    });
    if (it != refusals_.end()) {
      it->time_ns = wall;
      fresh = false;
    } else {
      neurosim_StationRefusal r{};
      std::strncpy(r.station_id, key.c_str(), neurosim_ID_MAX);
      std::memcpy(r.writer_guid, guid.data(), 16);
      r.reason = reason;
      r.time_ns = wall;
      refusals_.insert(refusals_.begin(), r);
      if (refusals_.size() > kMaxRefusals) {
        refusals_.pop_back();
        ++counters.unknown_ids_dropped;
      }
    }
  }
  if (!fresh) return;
  if (reason != neurosim_REFUSED_IDENTITY) ++counters.stations_refused;
  status_soon_.store(true, std::memory_order_release);
  limited_log("refused", "refused station '" + key + "': " + why);
}

std::size_t StationAdmission::copy_refusals(neurosim_StationRefusal* out, std::size_t cap) const {
  std::lock_guard<std::mutex> lk(refusal_mutex_);
  const std::size_t n = std::min(cap, refusals_.size());
  std::copy(refusals_.begin(), refusals_.begin() + static_cast<std::ptrdiff_t>(n), out);
  return n;
}

void StationAdmission::leave(const std::string& key, const char* why) {
  const auto it = slot_of_station_.find(key);
  if (it == slot_of_station_.end()) return;
  auto& s = slots_[static_cast<std::size_t>(it->second)];
  s.writer = 0;
  s.state.store(kSlotLeaving, std::memory_order_release);
  limited_log("leave", "station '" + key + "' left (" + why + "), slot " + std::to_string(it->second));
  slot_of_station_.erase(it);
}

void StationAdmission::writer_lost(dds_instance_handle_t writer) {
  for (auto it = slot_of_station_.begin(); it != slot_of_station_.end(); ++it)
    if (slots_[static_cast<std::size_t>(it->second)].writer == writer) {
      const std::string key = it->first;
      leave(key, "its writer lost liveliness");
      return;
    }
}

void StationAdmission::sweep(std::int64_t now, std::int64_t wall) {
  const auto idle_ns = static_cast<std::int64_t>(def_.station_idle_timeout_s * 1e9);
  struct Gone {
    std::string key;
    bool idle;  // reclaimed (counted), else its writer left
  };
  std::vector<Gone> gone;
  for (const auto& [key, i] : slot_of_station_) {
    const auto& s = slots_[static_cast<std::size_t>(i)];
    if (now - s.last_sample_mono_ns > idle_ns) {
      gone.push_back({key, true});
    } else if (directory_ != nullptr && !directory_->matched(s.writer).matched) {
      gone.push_back({key, false});
    }
  }
  for (const auto& g : gone) {
    if (g.idle) ++counters.stations_reclaimed;
    leave(g.key, g.idle ? "idle: no sample within the station idle timeout, slot reclaimed" : "its writer is gone");
  }
  if (directory_ != nullptr)
    for (const auto h : claims_.writers())
      if (!directory_->matched(h).matched) claims_.erase(h);
  std::lock_guard<std::mutex> lk(refusal_mutex_);
  refusals_.erase(std::remove_if(refusals_.begin(), refusals_.end(),
                                 [&](const neurosim_StationRefusal& r) { return wall - r.time_ns > kRefusalMemoryNs; }),
                  refusals_.end());
}

void StationAdmission::join(const std::string& key, const wire::Received<neurosim_ToolState>& rx,
                            const WriterInfo& w, const ReceiveTime& at, int slot) {
  auto& s = slots_[static_cast<std::size_t>(slot)];
  std::memcpy(s.station_id, rx.data.station_id, sizeof(s.station_id));
  const std::string tool(rx.data.tool_id);
  const auto& ids = def_.tool_ids;
  double vmax = kDefaultMaxSpeed;
  std::string tool_note;
  const auto ti = std::find(ids.begin(), ids.end(), tool);
  if (ti != ids.end()) {
    vmax = def_.tool_max_speed_m_per_s[static_cast<std::size_t>(ti - ids.begin())];
  } else if (!ids.empty()) {
    vmax = def_.tool_max_speed_m_per_s[0];
    tool_note = " (unknown tool '" + tool + "': using '" + ids[0] + "')";
  }
  ToolFilterDef fd;
  fd.max_speed_m_per_s = vmax;
  fd.workspace = def_.workspace;
  fd.max_future_s = def_.max_future_s;
  fd.max_rate_hz = def_.max_station_rate_hz;
  s.filter = ToolFilter(fd);
  s.tool = ti != ids.end() ? static_cast<int>(ti - ids.begin()) : 0;
  s.writer = rx.info.publication_handle;
  s.participant = w.participant;
  s.last_sample_mono_ns = at.monotonic_ns;
  s.accepted = 0;
  s.rejected_nonfinite = 0;
  s.rejected_jump = 0;
  s.rejected_workspace = 0;
  s.rejected_time = 0;
  s.rejected_sequence = 0;
  s.rejected_identity = 0;
  s.last_sequence = 0;
  s.last_rejected = false;
  s.state.store(kSlotActive, std::memory_order_release);
  slot_of_station_.emplace(key, slot);
  std::ostringstream os;
  os << "station '" << key << "' joined, slot " << slot << ", tool '" << tool << "', max speed "
     << vmax << " m/s" << tool_note;
  limited_log("join", os.str());
}

void StationAdmission::handle(const wire::Received<neurosim_ToolState>& rx, const ReceiveTime& at) {
  const std::string key(rx.key());
  const dds_instance_handle_t writer = rx.info.publication_handle;
  const auto bound = slot_of_station_.find(key);
  if (!rx.valid()) {
    // Only the bound writer may end its station (a dispose by another writer is ignored).
    if (bound == slot_of_station_.end()) return;
    if (rx.no_writers()) leave(key, "no writers / liveliness lost");
    else if (rx.disposed() && slots_[static_cast<std::size_t>(bound->second)].writer == writer)
      leave(key, "disposed");
    return;
  }
  auto identity_reject = [&](const std::string& why, bool refusal, const Guid& guid) {
    ++counters.rejected_identity;
    if (bound != slot_of_station_.end())
      slots_[static_cast<std::size_t>(bound->second)].rejected_identity.fetch_add(1, std::memory_order_relaxed);
    if (refusal) refuse(key, guid, neurosim_REFUSED_IDENTITY, why);
    else limited_log("identity", "rejected ToolState for '" + key + "': " + why);
  };
  const WriterLookup lookup = writer_info(writer, key, at.monotonic_ns);
  if (!lookup.info) {
    if (!lookup.refused) identity_reject(lookup.why, false, Guid{});
    return;
  }
  const WriterInfo& w = *lookup.info;
  if (key.empty() || w.claim != key)
    return identity_reject("the writer's partition claims '" + w.claim + "', not '" + key +
                               "' (a ToolState writer publishes in partition " +
                               wire::kStationPartitionPrefix + "<its station_id>)",
                           true, w.guid);
  if (bound != slot_of_station_.end() && slots_[static_cast<std::size_t>(bound->second)].writer != writer)
    return identity_reject("station id bound to another writer (until that writer is gone or idle " +
                               std::to_string(def_.station_idle_timeout_s) + " s)",
                           true, w.guid);
  int slot = bound != slot_of_station_.end() ? bound->second : -1;
  if (slot < 0) {
    int same_participant = 0;
    for (const auto& [k, i] : slot_of_station_)
      if (slots_[static_cast<std::size_t>(i)].participant == w.participant) ++same_participant;
    if (same_participant >= def_.max_stations_per_participant)
      return refuse(key, w.guid, neurosim_REFUSED_PARTICIPANT_LIMIT,
                    "its DDS participant already holds " + std::to_string(same_participant) +
                        " stations (max " + std::to_string(def_.max_stations_per_participant) +
                        " per participant)");
    for (std::size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i].state.load(std::memory_order_acquire) == kSlotFree) {
        slot = static_cast<int>(i);
        break;
      }
    if (slot < 0)
      return refuse(key, w.guid, neurosim_REFUSED_MAX_STATIONS,
                    "max_stations " + std::to_string(def_.max_stations) + " reached (" +
                        std::to_string(slot_of_station_.size()) + " active, some may be leaving)");
    join(key, rx, w, at, slot);
  }
  auto& s = slots_[static_cast<std::size_t>(slot)];
  s.last_sample_mono_ns = at.monotonic_ns;
  double q[4];
  const Verdict v = s.filter.check(rx.data, at, q);
  if (v == Verdict::Accepted) {
    PoseSample p;
    p.sequence = rx.data.sequence_number;
    p.source_time_ns = rx.data.source_time_ns;
    p.tool = s.tool;
    for (int i = 0; i < 3; ++i) p.position_m[i] = rx.data.position_m[i];
    for (int i = 0; i < 4; ++i) p.orientation[i] = q[i];
    s.pose.publish(p);
    if (on_pose_) on_pose_();  // wake the step thread
    s.accepted.fetch_add(1, std::memory_order_relaxed);
    s.last_sequence.store(p.sequence, std::memory_order_relaxed);
    s.last_rejected.store(false, std::memory_order_relaxed);
    return;
  }
  s.last_rejected.store(true, std::memory_order_relaxed);
  auto& c = counters;
  switch (v) {
    case Verdict::NonFinite: s.rejected_nonfinite.fetch_add(1, std::memory_order_relaxed); ++c.rejected_nonfinite; break;
    case Verdict::Jump: s.rejected_jump.fetch_add(1, std::memory_order_relaxed); ++c.rejected_jump; break;
    case Verdict::Workspace: s.rejected_workspace.fetch_add(1, std::memory_order_relaxed); ++c.rejected_workspace; break;
    case Verdict::Time: s.rejected_time.fetch_add(1, std::memory_order_relaxed); ++c.rejected_time; break;
    case Verdict::Sequence: s.rejected_sequence.fetch_add(1, std::memory_order_relaxed); ++c.rejected_sequence; break;
    case Verdict::Rate: ++c.rejected_rate; break;
    case Verdict::Accepted: break;
  }
  // A station sending garbage must not flood the log: at most N lines per second per cause.
  limited_log(to_string(v), "station '" + key + "': rejected ToolState " +
                                std::to_string(rx.data.sequence_number) + " (" + to_string(v) +
                                "), keeping the last good pose");
}

}  // namespace neurosim::service
