// The viewer's DDS side: readers of MeshTopology (transient-local: a late joiner gets
// every mesh), Deformation, ToolState, ContactModel and SimStatus (liveliness: server gone /
// back; content: tier and its update rate), all with the server's topic prefix. Read-only: the
// viewer writes nothing, so it cannot disturb the simulation. poll() is non-blocking and runs on the render thread.
#pragma once

#include "viewer_client/viewer/state.hpp"

#include <cstdint>
#include <memory>
#include <string>

namespace neurosim::viewer {

struct DdsClientOptions {
  int domain = -1;           // -1: the CYCLONEDDS_URI configuration's default
  std::string topic_prefix;  // as neurosim-server --topic-prefix
};

class DdsClient {
 public:
  // Throws std::runtime_error when DDS cannot start (e.g. CYCLONEDDS_URI unset).
  explicit DdsClient(const DdsClientOptions& options);
  ~DdsClient();
  DdsClient(const DdsClient&) = delete;
  DdsClient& operator=(const DdsClient&) = delete;

  // Takes everything that arrived into `state`; returns whether anything changed.
  bool poll(ViewerState& state);
  // Blocks until any of the readers has data or timeout_s passes (the render loop's idle wait).
  void wait(double timeout_s);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::viewer
