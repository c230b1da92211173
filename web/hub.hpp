// The WebSocket clients of the bridge: at most max_clients outboxes, and the newest of every
// message (topology, one frame per mesh with its keyframe, status, stations) so that a client
// joining at any time starts from the current state. The DDS thread publishes, each client's
// sender thread takes from its own outbox; thread-safe.
#pragma once

#include "web/client_outbox.hpp"
#include "web/protocol.hpp"

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace neurosim::web {

struct HubOptions {
  std::size_t max_clients = 16;  // the (max_clients + 1)-th client is refused
};

struct HubCounters {
  std::size_t clients = 0;
  std::size_t max_clients = 0;
  std::uint64_t joined = 0;   // since start
  std::uint64_t refused = 0;  // over max_clients
  std::vector<ClientCounters> per_client;
};

class Hub {
 public:
  explicit Hub(HubOptions options = {});

  // A new client's outbox, primed with the current state; null when max_clients are connected.
  std::shared_ptr<ClientOutbox> join(std::string peer);
  // The client left: its outbox is closed and forgotten.
  void leave(const std::shared_ptr<ClientOutbox>& outbox);
  // Closes every outbox (shutdown): the senders stop.
  void close_all();

  void publish_topology(TopologyPtr topology);  // forgets the frames of older generations
  void publish_frame(FramePtr frame);
  void publish_status(MessagePtr status);
  void publish_stations(MessagePtr stations);

  std::size_t clients() const;
  std::size_t max_clients() const { return options_.max_clients; }
  HubCounters counters() const;

 private:
  const HubOptions options_;
  mutable std::mutex m_;
  std::vector<std::shared_ptr<ClientOutbox>> clients_;
  std::uint64_t next_id_ = 1;
  std::uint64_t joined_ = 0, refused_ = 0;
  TopologyPtr topology_;
  std::map<std::uint16_t, FramePtr> frames_;  // newest per mesh index (a delta holds its base)
  MessagePtr status_, stations_;
};

}  // namespace neurosim::web
