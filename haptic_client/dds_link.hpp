// The haptic client's DDS side: ToolState writer (called from the loop thread), and a DDS thread
// that takes this station's newest ContactModel into a lock-free slot and follows the server's
// SimStatus liveliness (server gone / back).
#pragma once

#include "common/triple_buffer.hpp"
#include "haptic_client/link.hpp"

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

struct neurosim_ContactModel;  // generated (idl/neurosim.idl)

namespace neurosim::haptic {

struct DdsLinkOptions {
  std::string station_id;
  std::string tool_id = "probe";
  // Topics are wire::topic_name<T>(topic_prefix): the server's names under its --topic-prefix
  // (empty: the wire contract's names); tests use a unique prefix.
  std::string topic_prefix;
  // ToolStates are written by a publisher thread (the loop only posts them lock-free), at this
  // SCHED_FIFO priority where permitted (0: normal priority), so DDS locks never stall the loop.
  int publisher_rt_priority = 70;
  // The thread taking ContactModels, likewise (0: normal priority).
  int receiver_rt_priority = 60;
  // Thread names (ps, top, perf) and optional CPU sets (empty: any CPU) of those two threads.
  std::string publisher_thread_name = "nh-publish";
  std::string receiver_thread_name = "nh-receive";
  std::vector<int> publisher_cpus, receiver_cpus;
  // Told once by each thread, at its start, what scheduling it was granted (or why not).
  void (*sched_log)(const char* line) = nullptr;
};

// Whether the server refused this station (SimStatus.refused lists this link's own writer).
// MaxStations is transient (a slot may free up: the server admits the station on a later
// sample); ParticipantLimit and Identity are not (another writer holds the id, or the
// participant holds its maximum of stations), and neurosim-haptic exits with status 3.
enum class Refusal { None, MaxStations, ParticipantLimit, Identity };
const char* describe(Refusal r);
inline bool permanent(Refusal r) { return r == Refusal::ParticipantLimit || r == Refusal::Identity; }

struct DdsLinkCounters {
  std::uint64_t models_received = 0;  // for this station
  std::uint64_t models_rejected = 0;  // tool_sample_rejected set by the server
  std::uint64_t server_lost = 0;      // SimStatus writers went from alive to none
  std::uint64_t server_seen = 0;      // SimStatus writers appeared (first time or reconnect)
  std::uint64_t write_errors = 0;     // ToolState writes that failed
  // Server steps whose ContactModel never reached this station (gaps in server_step between
  // consecutive models: lost on the network or overwritten in the keep-last-1 reader).
  std::uint64_t models_skipped = 0;
  // Rigid planes dropped on arrival (non-finite, or normal not unit within kUnitNormalTolerance).
  std::uint64_t planes_dropped = 0;
};

// Copies one received ContactModel into the loop's form (reference time: the answered
// ToolState's source time, else arrival_ns). Rigid planes are checked one by one and invalid
// ones dropped; returns how many were dropped.
std::size_t copy_contact_model(const neurosim_ContactModel& c, std::int64_t arrival_ns,
                               ContactModelData& m);

class DdsLink : public Link {
 public:
  explicit DdsLink(const DdsLinkOptions& options);  // starts the DDS thread
  ~DdsLink() override;                              // stops it
  DdsLink(const DdsLink&) = delete;
  DdsLink& operator=(const DdsLink&) = delete;

  // Loop thread: lock-free hand-off to the publisher thread (never blocks).
  void publish(const ToolSample& s) override;
  bool take_model(ContactModelData& out) override { return slot_.take(out); }
  bool server_alive() override { return alive_.load(std::memory_order_acquire); }
  DdsLinkCounters counters() const;
  // Blocks until a ContactModel writer (the server) is matched or the timeout passes.
  bool wait_for_server(double timeout_s) const;
  // The newest refusal of this station's writer the server published (None: not refused, or
  // the refusal is older than 2 s: admitted since or gone).
  Refusal refusal() const;

 private:
  void run();
  void run_publisher();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  common::TripleBuffer<ContactModelData> slot_;
  common::TripleBuffer<ToolSample> outgoing_;
  std::atomic<bool> alive_{true};
  std::atomic<int> refusal_{0};                  // Refusal
  std::atomic<std::int64_t> refusal_time_ns_{0};  // server time of that refusal (Unix epoch)
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> models_{0}, rejected_{0}, lost_{0}, seen_{0}, write_errors_{0},
      skipped_{0}, planes_dropped_{0};
  std::thread thread_;
  std::thread publisher_;
};

}  // namespace neurosim::haptic
