// The bridge's DDS side: a read-only participant with readers of MeshTopology (transient-local:
// the bridge gets every mesh whenever it starts), Deformation, ContactModel and SimStatus
// (liveliness: server gone / back), all with the server's topic prefix. It creates no writer,
// so it cannot disturb the simulation. Its thread feeds an ObserverState and publishes the
// resulting messages to the Hub: frames as they arrive, stations at most stations_hz, the status
// on every SimStatus, liveliness change and once per second.
#pragma once

#include "web/hub.hpp"
#include "web/observer_state.hpp"

#include <functional>
#include <memory>
#include <string>

namespace neurosim::web {

struct DdsSourceOptions {
  int domain = -1;           // -1: the CYCLONEDDS_URI configuration's default
  std::string topic_prefix;  // as neurosim-server --topic-prefix
  double stations_hz = 30;   // stations message at most this often, unit Hz
};

class DdsSource {
 public:
  using Log = std::function<void(const std::string&)>;
  // Starts the thread. Throws std::runtime_error when DDS cannot start (e.g. CYCLONEDDS_URI
  // unset).
  DdsSource(const DdsSourceOptions& options, Hub& hub, Log log);
  ~DdsSource();  // stops and joins the thread
  DdsSource(const DdsSource&) = delete;
  DdsSource& operator=(const DdsSource&) = delete;

  ObserverCounters counters() const;
  bool server_alive() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::web
