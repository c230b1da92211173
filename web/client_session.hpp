// The sender of one WebSocket client: takes what its outbox holds and sends it in protocol
// order (topology, status, stations, frames), so the page can always decode what it gets:
// frames of another topology generation are skipped, and a delta frame goes out after its FULL
// keyframe when this client has not had that one (it joined late, or the FULL frame was replaced
// in the outbox by the delta). No sockets here: `send` does the writing (the HTTP server's
// WebSocket write, or a test's recorder), and may block on a slow client without holding up
// any other one (each client has its own sender thread).
#pragma once

#include "web/client_outbox.hpp"
#include "web/protocol.hpp"

#include <chrono>
#include <functional>
#include <memory>
#include <vector>

namespace neurosim::web {

class ClientSession {
 public:
  // Writes one message; false when the connection failed (nothing more is sent then).
  using Send = std::function<bool(const Message&)>;

  ClientSession(std::shared_ptr<ClientOutbox> outbox, Send send);

  // Sends until the outbox closes or a send fails (the sender thread's body).
  void run(std::chrono::milliseconds poll = std::chrono::milliseconds(200));
  // Sends one batch; false when a send failed.
  bool send(ClientOutbox::Pending& batch);

 private:
  bool write(const Message& m, bool frame, bool keyframe);

  std::shared_ptr<ClientOutbox> outbox_;
  Send send_;
  bool have_topology_ = false;
  std::uint32_t generation_ = 0;            // of the topology this client has
  std::vector<std::uint64_t> full_serial_;  // per mesh index: FULL frame it can add deltas to
};

}  // namespace neurosim::web
