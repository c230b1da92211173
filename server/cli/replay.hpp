// Offline replay of recorded tool trajectories (idl/recording.proto) through a Simulation,
// deterministically: one step per distinct sample time, all stations together, each with its
// newest sample so far (a station whose recording has not started is left out of the step, as
// the live server leaves out a station that has sent no pose; one whose recording has ended
// keeps its last pose). neurosim-replay and accuracy_bench drive their runs through this.
#pragma once

#include "recording.pb.h"
#include "server/interaction/simulation.hpp"
#include "server/model/model.hpp"
#include "server/service/tool_filter.hpp"

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace neurosim::replay {

// One recording: one station.
struct Station {
  std::string file;  // where it came from (messages)
  std::string id;    // the header's station id, else the file's stem
  int tool{0};       // index into the scene's tools (the header's tool id)
  std::vector<recording::Sample> samples;
};

// Reads `file` as a station of `model`. Throws std::runtime_error naming the file when it is
// missing or malformed, or its tool is not one of the scene's (the scene's tools listed), or
// its station id has a comma, quote or line break (it is written to CSV files).
Station load_station(const std::string& file, const scene::Model& model);

// A sample the live server's filter would reject (server/service/tool_filter.hpp).
struct RejectedSample {
  std::size_t index{0};  // in the recording, from 0
  double time_s{0.0};    // its time, unit s
  service::Verdict why{service::Verdict::Accepted};
};

// The live server's filter for `sim`'s scene: the workspace is the bounding box of every mesh's
// rest vertices enlarged by margin_m (the server's --workspace-margin), and each station's
// tool has its max_speed_m_per_s; other limits are the server's defaults.
service::Workspace scene_workspace(const interaction::Simulation& sim,
                                   double margin_m = service::kDefaultWorkspaceMarginM);

// Runs every sample of `station` through the live server's ToolFilter (a new one per station,
// as for a new writer) with the sample's own time as its receive time and its source time;
// samples recorded without tool sequence numbers (all 0) are numbered in their order. Returns
// the samples it rejects, in order; with remove, they are also taken out of station.samples (the
// station keeps its last accepted pose, as on the live server).
std::vector<RejectedSample> filter_station(Station& station, const scene::Model& model,
                                           const service::Workspace& workspace, bool remove);

// The pose the live server builds from a ToolState (server/service/server.cpp): the quaternion
// normalized, the shaft axis the tool frame's +z rotated into the scene frame.
interaction::ToolPose pose_of(const recording::Sample& sample, int tool);

// Every distinct sample time of the stations, ascending (one step each). max_rate_hz > 0: times
// closer than 1 / max_rate_hz to the previous step are left out (the last time is always kept),
// so a 1 kHz recording can be replayed at, e.g., 50 steps per second of recording by a slow tier.
std::vector<double> step_times(const std::vector<Station>& stations, double max_rate_hz = 0.0);

// What the callback sees after each step.
struct StepView {
  std::size_t index{0};  // step number, from 0
  std::size_t count{0};  // steps in the replay
  double time_s{0.0};    // sample time of the step, unit s
  const std::vector<interaction::ToolPose>* poses{nullptr};  // the stations taking part
  const std::vector<int>* station_of_pose{nullptr};           // index into the stations
  const std::vector<interaction::ToolContact>* contacts{nullptr};  // one per pose
  const interaction::StepStats* stats{nullptr};
};

// Steps `sim` once per step_times(stations) and calls on_step after each; each pose's station is
// its recording's index (with rigid obstacles the step holds each station's tool outside the bone
// by its own proxy, as the live server does per slot). Station ids must be
// unique (throws std::invalid_argument naming both files); throws what Simulation::step throws.
// Deterministic when `sim` was built with tier_worker_thread = false.
void run(interaction::Simulation& sim, const std::vector<Station>& stations,
         const std::function<void(const StepView&)>& on_step, double max_rate_hz = 0.0);

}  // namespace neurosim::replay
