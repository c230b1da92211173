// What is waiting to be sent to one WebSocket client, latest wins: at most one topology, one
// frame per mesh, one status and one stations message. A new one replaces the one still waiting
// (a replaced frame counts as dropped), so a slow browser gets fewer frames and the bridge's
// memory does not grow with it. Filled by the DDS thread (through the Hub), emptied by the
// client's sender thread (ClientSession); thread-safe.
#pragma once

#include "web/protocol.hpp"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace neurosim::web {

// Counters of one client (updated by the sender thread, read by /api/stats).
struct ClientCounters {
  std::uint64_t id = 0;
  std::string peer;        // "address:port" of the browser
  double connected_s = 0;  // unit s
  std::uint64_t messages_sent = 0;
  std::uint64_t frames_sent = 0;  // deformation frames, keyframes included
  // FULL frames sent ahead of a delta the client could not decode otherwise.
  std::uint64_t keyframes_sent = 0;
  std::uint64_t frames_dropped = 0;  // replaced before they could be sent (latest wins)
  std::uint64_t bytes_sent = 0;
  bool failed = false;  // a send failed: nothing more goes to this client
};

class ClientOutbox {
 public:
  struct Pending {
    TopologyPtr topology;
    std::map<std::uint16_t, FramePtr> frames;  // by mesh index
    MessagePtr status;
    MessagePtr stations;
    bool empty() const { return !topology && frames.empty() && !status && !stations; }
  };

  ClientOutbox(std::uint64_t id, std::string peer);

  // A new topology; frames still waiting for another generation are dropped.
  void put_topology(TopologyPtr topology);
  void put_frame(FramePtr frame);
  void put_status(MessagePtr status);
  void put_stations(MessagePtr stations);
  // No more messages: take() returns false from now on.
  void close();
  bool closed() const;

  // Waits up to `timeout` for something to send and moves it into `out` (emptied first).
  // Returns false once the outbox is closed.
  bool take(Pending& out, std::chrono::milliseconds timeout);

  // Sender side.
  void note_sent(std::size_t bytes, bool frame, bool keyframe);
  void note_failed();
  void note_dropped(std::uint64_t frames);

  ClientCounters counters() const;
  std::uint64_t id() const { return id_; }

 private:
  const std::uint64_t id_;
  const std::string peer_;
  const std::chrono::steady_clock::time_point connected_;
  mutable std::mutex m_;
  std::condition_variable cv_;
  Pending pending_;
  bool closed_ = false;
  ClientCounters counters_;
};

}  // namespace neurosim::web
