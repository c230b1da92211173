// Station admission (docs/ARCHITECTURE.md "Station identity"): the DDS thread's side of the
// stations. Each ToolState sample is checked against its writer's claim (station_identity.hpp),
// bound to the station slot its id holds or joins (at most max_stations, at most
// max_stations_per_participant per DDS participant), filtered (tool_filter.hpp), and its pose
// handed to the slot's triple buffer (pose_handoff.hpp), which the step thread reads without
// ever waiting. Refusals are kept (at most 16, newest first) for SimStatus and flagged so the
// status goes out at once; idle stations and writers that left are swept.
//
// No DDS entity is created here: the writers' discovery data come through a WriterDirectory
// (the server's ToolState reader; a table in the tests), samples through handle().
#pragma once

#include "idl/wire/dds.hpp"
#include "server/service/log_limiter.hpp"
#include "server/service/pose_handoff.hpp"
#include "server/service/station_identity.hpp"
#include "server/service/tool_filter.hpp"

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace neurosim::service {

// Where a ToolState writer's discovery data come from.
class WriterDirectory {
 public:
  virtual ~WriterDirectory() = default;
  // The writer as discovery sees it now (matched = false: gone, or never matched).
  virtual wire::MatchedPublication matched(dds_instance_handle_t writer) const = 0;
};

enum SlotState : int { kSlotFree = 0, kSlotActive = 1, kSlotLeaving = 2 };

// One station. The DDS thread owns join (Free → Active) and leave (Active → Leaving); the step
// thread retires (Leaving → Free). Poses cross through the triple buffer.
struct StationSlot {
  std::atomic<int> state{kSlotFree};
  char station_id[neurosim_ID_MAX + 1]{};  // written by the DDS thread before state = Active
  common::TripleBuffer<PoseSample> pose;
  std::atomic<bool> last_rejected{false};
  std::atomic<std::uint64_t> accepted{0}, rejected_nonfinite{0}, rejected_jump{0}, last_sequence{0},
      rejected_workspace{0}, rejected_time{0}, rejected_sequence{0}, rejected_identity{0};
  std::atomic<bool> in_contact{false};  // written by the step thread
  // DDS thread only.
  ToolFilter filter;
  int tool{0};
  dds_instance_handle_t writer{0};      // the ToolState writer this station is bound to
  Guid participant{};                   // that writer's participant
  std::int64_t last_sample_mono_ns{0};  // newest sample of the bound writer (any verdict)
};

struct StationAdmissionDef {
  int max_stations{8};                      // slots (0: stations off)
  int max_stations_per_participant{2};      // >= 1
  double station_idle_timeout_s{2.0};       // a station with no sample this long frees its slot, unit s
  WriterLimits writers{};                   // the table of ToolState writers (station_identity.hpp)
  Workspace workspace{};                    // scene bounding box + margin
  double max_future_s{1.0};                 // unit s
  double max_station_rate_hz{2000.0};       // samples per second per station (burst ToolFilterDef::rate_burst, 200)
  std::vector<std::string> tool_ids;        // scene tools, in order
  std::vector<double> tool_max_speed_m_per_s;  // per scene tool, unit m/s
  int log_lines_per_second{5};              // per cause
  // Throws std::invalid_argument naming the bad field.
  void validate() const;
};

// Totals since start (per station counts are in the slots).
struct AdmissionCounters {
  std::atomic<std::uint64_t> rejected_nonfinite{0}, rejected_jump{0}, rejected_workspace{0},
      rejected_time{0}, rejected_sequence{0}, rejected_identity{0}, rejected_rate{0},
      stations_refused{0}, stations_reclaimed{0}, unknown_ids_dropped{0}, writers_evicted{0};
};

class StationAdmission {
 public:
  static constexpr std::size_t kMaxRefusals = 16;                // SimStatus.refused
  static constexpr std::int64_t kRefusalMemoryNs = 5000000000;   // forgotten 5 s after the last sample

  // `log` gets one line each (rate-limited per cause here); `on_pose` (may be empty) runs after
  // each pose handed to a slot (the event step mode's wake-up).
  StationAdmission(StationAdmissionDef def, std::function<void(const std::string&)> log,
                   std::function<void()> on_pose = {});

  // Before the reader exists: the identity filter on the ToolState topic (Cyclone's receive
  // thread drops a cached writer's samples for other ids).
  void install_filter(dds_entity_t topic) { claims_.install_filter(topic); }
  // The writers' discovery data (must outlive this object's use on the DDS thread).
  void set_directory(const WriterDirectory* directory) { directory_ = directory; }

  // ---- DDS thread ----
  void handle(const wire::Received<neurosim_ToolState>& rx, const ReceiveTime& at);
  // A writer lost liveliness: its station (if any) leaves at once.
  void writer_lost(dds_instance_handle_t writer);
  // Every ~100 ms: idle stations and stations whose writer is gone free their slot; writers no
  // longer matched and old refusals are forgotten.
  void sweep(std::int64_t now_mono_ns, std::int64_t now_wall_ns);

  // ---- step thread ----
  std::vector<StationSlot>& slots() { return slots_; }
  const std::vector<StationSlot>& slots() const { return slots_; }

  // ---- any thread ----
  // A refusal is new since the last take_status_soon(): publish SimStatus early.
  bool status_soon() const { return status_soon_.load(std::memory_order_acquire); }
  void clear_status_soon() { status_soon_.store(false, std::memory_order_release); }
  // Copies the recent refusals (newest first) into out[0..cap); returns how many.
  std::size_t copy_refusals(neurosim_StationRefusal* out, std::size_t cap) const;
  std::uint64_t log_lines_suppressed() const { return suppressed_lines_.load(std::memory_order_relaxed); }
  // identity rejections counted here plus those the topic filter dropped.
  std::uint64_t rejected_identity() const {
    return counters.rejected_identity.load() + claims_.filtered();
  }
  const WriterClaims& writers() const { return claims_; }
  const StationAdmissionDef& def() const { return def_; }

  AdmissionCounters counters;

 private:
  struct WriterLookup {
    std::optional<WriterInfo> info;  // nullopt: not admitted (why says it)
    bool refused{false};             // a refusal was published for it
    std::string why;
  };
  WriterLookup writer_info(dds_instance_handle_t writer, const std::string& key, std::int64_t now_mono);
  bool pinned(dds_instance_handle_t writer) const;
  void join(const std::string& key, const wire::Received<neurosim_ToolState>& rx, const WriterInfo& w,
            const ReceiveTime& at, int slot);
  void leave(const std::string& key, const char* why);
  void refuse(const std::string& key, const Guid& writer_guid, neurosim_RefusalReason reason,
              const std::string& why);
  void limited_log(const char* cause, const std::string& line);

  StationAdmissionDef def_;
  std::function<void(const std::string&)> log_;
  std::function<void()> on_pose_;
  const WriterDirectory* directory_{nullptr};
  // Declared before the slots: the topic filter points here and must outlive the reader.
  WriterClaims claims_;
  std::vector<StationSlot> slots_;
  std::unordered_map<std::string, int> slot_of_station_;  // DDS thread only
  LogLimiter log_limit_;
  std::atomic<std::uint64_t> suppressed_lines_{0};
  mutable std::mutex refusal_mutex_;
  std::vector<neurosim_StationRefusal> refusals_;  // newest first, at most kMaxRefusals
  std::atomic<bool> status_soon_{false};
};

}  // namespace neurosim::service
