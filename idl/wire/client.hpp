// The client side of a session, one implementation for every station (neurosim-haptic), viewer
// (neurosim-viewer) and observer (neurosim-web): the participant (DDS domain), the topics under
// the run's prefix (as neurosim-server --topic-prefix), and the server's SimStatus reader, whose
// liveliness says whether the server is alive, attached to a waitset for its data and its
// liveliness; each client adds its own readers (and, a station, its writer) to the same
// participant and waitset.
#pragma once

#include "idl/wire/dds.hpp"

#include <string>

namespace neurosim::wire {

struct ClientOptions {
  int domain{-1};            // -1: the CYCLONEDDS_URI configuration's default
  std::string topic_prefix;  // as neurosim-server --topic-prefix
};

class ClientSession {
 public:
  // Attachment tokens of the server's SimStatus on waitset(); clients use others for theirs.
  static constexpr dds_attach_t kStatusData = 1001;
  static constexpr dds_attach_t kStatusLiveliness = 1002;

  explicit ClientSession(const ClientOptions& options = {});
  ClientSession(const ClientSession&) = delete;
  ClientSession& operator=(const ClientSession&) = delete;

  const Participant& participant() const { return pp_; }
  // The topic of T under the run's prefix, on this participant.
  template <class T>
  Topic<T> topic() const {
    return Topic<T>(pp_, topic_name<T>(prefix_));
  }
  const std::string& topic_prefix() const { return prefix_; }
  Reader<neurosim_SimStatus>& status() { return status_; }
  Waitset& waitset() { return ws_; }
  // The server's SimStatus writer is alive (its liveliness lease, 500 ms).
  bool server_alive() { return status_.liveliness().alive_count > 0; }

 private:
  Participant pp_;
  std::string prefix_;
  Topic<neurosim_SimStatus> status_topic_;
  Reader<neurosim_SimStatus> status_;
  Waitset ws_;
};

}  // namespace neurosim::wire
