#include "server/cli/replay.hpp"

#include "common/tool_pose.hpp"
#include "idl/wire/recording_io.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace neurosim::replay {

Station load_station(const std::string& file, const scene::Model& model) {
  if (!std::filesystem::exists(file)) throw std::runtime_error(file + ": no such recording file");
  wire::Recording rec = wire::read_recording(file);
  Station st;
  st.file = file;
  st.id = rec.header.station_id().empty() ? std::filesystem::path(file).stem().string()
                                          : rec.header.station_id();
  const std::string& tool_id = rec.header.tool_id();
  int tool = -1;
  for (std::size_t t = 0; t < model.tools.size(); ++t) {
    if (model.tools[t].id == tool_id) tool = static_cast<int>(t);
  }
  if (tool < 0) {
    std::string known;
    for (const auto& t : model.tools) known += (known.empty() ? "" : ", ") + t.id;
    throw std::runtime_error(file + ": tool '" + tool_id + "' is not a tool of scene " +
                             model.source + " (" + known + ")");
  }
  st.tool = tool;
  if (st.id.find_first_of(",\"\r\n") != std::string::npos) {
    throw std::runtime_error(file + ": station id '" + st.id +
                             "' has a comma, quote or line break (not written to forces.csv)");
  }
  st.samples = std::move(rec.samples);
  return st;
}

interaction::ToolPose pose_of(const recording::Sample& s, int tool) {
  interaction::ToolPose tp;
  tp.tip_m = interaction::Vec3(s.position_m().x(), s.position_m().y(), s.position_m().z());
  const auto& o = s.orientation();
  const double qn = std::sqrt(o.w() * o.w() + o.x() * o.x() + o.y() * o.y() + o.z() * o.z());
  const double q[4] = {o.w() / qn, o.x() / qn, o.y() / qn, o.z() / qn};
  const std::array<double, 3> a = common::rotated_z(q);
  tp.axis = interaction::Vec3(a[0], a[1], a[2]);
  tp.tool = tool;
  return tp;
}

std::vector<double> step_times(const std::vector<Station>& stations, double max_rate_hz) {
  if (!(max_rate_hz >= 0.0) || !std::isfinite(max_rate_hz)) {
    throw std::invalid_argument("replay: max rate must be finite and >= 0 Hz");
  }
  std::vector<double> times;
  for (const auto& st : stations)
    for (const auto& s : st.samples) times.push_back(s.time_s());
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  if (max_rate_hz > 0.0 && times.size() > 2) {
    const double min_dt = 1.0 / max_rate_hz;
    std::vector<double> kept{times.front()};
    for (std::size_t i = 1; i + 1 < times.size(); ++i)
      if (times[i] - kept.back() >= min_dt) kept.push_back(times[i]);
    kept.push_back(times.back());
    times = std::move(kept);
  }
  return times;
}

void run(interaction::Simulation& sim, const std::vector<Station>& stations,
         const std::function<void(const StepView&)>& on_step, double max_rate_hz) {
  for (std::size_t i = 0; i < stations.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (stations[i].id == stations[j].id) {
        throw std::invalid_argument(stations[i].file + ": station '" + stations[i].id +
                                    "' is also recorded in " + stations[j].file);
      }
  const std::vector<double> times = step_times(stations, max_rate_hz);
  std::vector<std::size_t> next(stations.size(), 0);  // first sample not yet taken
  std::vector<interaction::ToolPose> poses;
  std::vector<int> station_of_pose;
  std::vector<interaction::ToolContact> contacts;
  interaction::StepStats stats;
  StepView view;
  view.count = times.size();
  view.poses = &poses;
  view.station_of_pose = &station_of_pose;
  view.contacts = &contacts;
  view.stats = &stats;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double t = times[k];
    poses.clear();
    station_of_pose.clear();
    for (std::size_t i = 0; i < stations.size(); ++i) {
      const auto& samples = stations[i].samples;
      while (next[i] < samples.size() && samples[next[i]].time_s() <= t) ++next[i];
      if (next[i] == 0) continue;  // not started yet: not in this step
      poses.push_back(pose_of(samples[next[i] - 1], stations[i].tool));
      station_of_pose.push_back(static_cast<int>(i));
    }
    sim.step(poses, contacts, stats);
    view.index = k;
    view.time_s = t;
    on_step(view);
  }
}

}  // namespace neurosim::replay
