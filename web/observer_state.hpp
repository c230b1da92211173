// What the bridge knows about the simulation, fed from DDS samples (dds_source.hpp) or directly
// (tests), and turned into protocol messages (protocol.hpp) once for every client: the meshes
// (MeshTopology), the newest FULL frame of each (so a delta can be sent with its keyframe), the
// stations (ContactModel: force, contact, tool pose), the newest SimStatus and whether the
// server is alive. No threads, no DDS: one thread owns it.
//
// Bad samples never throw out of ingest_*(): they are counted, the first few are reported
// through the warning callback (naming the mesh, frame or station), and the state is kept.
#pragma once

#include "idl/wire/types.hpp"
#include "web/protocol.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace neurosim::web {

struct ObserverCounters {
  std::uint64_t topologies = 0;      // accepted MeshTopology samples
  std::uint64_t frames = 0;          // Deformation frames accepted (to be forwarded)
  std::uint64_t frames_waiting = 0;  // no topology yet, or a delta without its FULL frame
  std::uint64_t contacts = 0;        // accepted ContactModel samples
  std::uint64_t statuses = 0;        // accepted SimStatus samples
  std::uint64_t malformed_topology = 0;
  std::uint64_t malformed_frame = 0;  // sizes, revision, encoding, non-finite values
  std::uint64_t malformed_contact = 0;
  std::uint64_t malformed_status = 0;  // unknown tier, non-finite or negative rates
  std::uint64_t server_seen = 0;       // SimStatus writer appeared (first time or again)
  std::uint64_t server_lost = 0;       // SimStatus writer went away
};

// The bridge's own numbers the status message carries next to the server's.
struct BridgeRates {
  double deformation_hz = 0;  // Deformation frames accepted per second and mesh, unit Hz
  std::size_t clients = 0;
  std::size_t max_clients = 0;
};

// One station as the page shows it (newest ContactModel).
struct StationView {
  std::array<double, 3> force_n{};  // f0 while in contact, else zero, unit N
  std::array<double, 3> tip_m{};    // contact reference tip (the tool tip when not in contact), m
  std::array<double, 3> axis{{0, 0, 1}};  // shaft direction, unit vector, tip towards handle
  bool in_contact = false;
  std::string mesh;                 // mesh touched ("" none)
  std::int64_t server_time_ns = 0;  // unit ns (Unix epoch)
};

// The paper's rule for the tool colour with f = |F| / force_unit_n (F in N):
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)). The page computes the same.
std::array<double, 3> force_colour(double force_n, double force_unit_n = 1.0);

class ObserverState {
 public:
  using Warn = std::function<void(const std::string&)>;
  explicit ObserverState(Warn warn = {}, int max_warnings_per_kind = 5);

  // A new or replaced mesh: every mesh gets the next generation (indices are by id), the FULL
  // frames kept so far are forgotten. Returns the new topology, or null when the sample is bad.
  TopologyPtr ingest_topology(const neurosim_MeshTopology& t);
  // The frame to forward, or null (bad sample; no topology yet; a delta whose FULL frame was not
  // received).
  FramePtr ingest_deformation(const neurosim_Deformation& d);
  // Whether the stations changed.
  bool ingest_contact(const neurosim_ContactModel& c);
  bool remove_station(std::string_view station);  // its instance was disposed
  bool ingest_status(const neurosim_SimStatus& s);
  bool set_server_alive(bool alive);

  TopologyPtr topology() const { return topology_; }  // null until a mesh arrived
  MessagePtr stations_message() const;
  MessagePtr status_message(const BridgeRates& rates) const;
  const std::map<std::string, StationView>& stations() const { return stations_; }
  bool server_alive() const { return server_alive_; }
  const ObserverCounters& counters() const { return counters_; }

 private:
  struct Mesh {
    std::string id;
    std::uint32_t revision = 0;
    std::vector<float> rest_m;             // 3 per vertex, unit m
    std::vector<std::uint32_t> triangles;  // 3 per surface triangle
    std::string info_json;                 // material, priority, provenance (a JSON object)
    FramePtr last_full;                    // newest FULL frame of this generation
    std::uint64_t last_full_frame = 0;     // its Deformation.frame
    std::uint64_t vertex_count() const { return rest_m.size() / 3; }
  };
  void warn(int kind, const std::string& message);
  void rebuild_topology();

  Warn warn_;
  int max_warnings_;
  std::array<int, 4> warned_{};
  std::vector<Mesh> meshes_;  // sorted by id: the mesh index is the position
  std::string scene_name_;
  std::uint32_t generation_ = 0;
  std::uint64_t next_full_serial_ = 1;
  TopologyPtr topology_;
  std::map<std::string, StationView> stations_;
  bool server_alive_ = false;
  bool status_received_ = false;
  std::string status_json_;  // the newest valid SimStatus, as sent (a JSON object)
  ObserverCounters counters_;
};

}  // namespace neurosim::web
