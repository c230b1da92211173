#include "server/cli/replay.hpp"

#include "common/tool_pose.hpp"
#include "idl/wire/recording_io.hpp"
#include "idl/wire/types.hpp"

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

service::Workspace scene_workspace(const interaction::Simulation& sim, double margin_m) {
  service::WorkspaceBounds bounds;
  for (int m = 0; m < sim.num_meshes(); ++m)
    for (const auto& x : sim.mesh(m).vertices()) bounds.add(x.data());
  return bounds.enlarged(margin_m);
}

std::vector<RejectedSample> filter_station(Station& station, const scene::Model& model,
                                           const service::Workspace& workspace, bool remove) {
  service::ToolFilterDef def;
  def.max_speed_m_per_s = model.tools.at(static_cast<std::size_t>(station.tool)).max_speed_m_per_s;
  def.workspace = workspace;
  service::ToolFilter filter(def);
  const bool numbered = std::any_of(station.samples.begin(), station.samples.end(),
                                    [](const recording::Sample& s) { return s.tool_sequence() != 0; });
  std::vector<RejectedSample> rejected;
  std::vector<recording::Sample> kept;
  for (std::size_t i = 0; i < station.samples.size(); ++i) {
    const recording::Sample& s = station.samples[i];
    neurosim_ToolState ts{};
    ts.position_m[0] = s.position_m().x();
    ts.position_m[1] = s.position_m().y();
    ts.position_m[2] = s.position_m().z();
    ts.orientation[0] = s.orientation().w();
    ts.orientation[1] = s.orientation().x();
    ts.orientation[2] = s.orientation().y();
    ts.orientation[3] = s.orientation().z();
    ts.velocity_m_per_s[0] = s.velocity_m_per_s().x();
    ts.velocity_m_per_s[1] = s.velocity_m_per_s().y();
    ts.velocity_m_per_s[2] = s.velocity_m_per_s().z();
    ts.sequence_number = numbered ? s.tool_sequence() : i + 1;
    // Received when it was sampled: the recording's own clock is the only one there is. A time
    // no int64 of ns holds is non-finite to the filter's time checks as well.
    const double t_ns = 1e9 * s.time_s();
    const bool time_ok = std::isfinite(t_ns) && std::abs(t_ns) < 9e18;
    service::Verdict v = service::Verdict::NonFinite;
    if (time_ok) {
      const auto ns = static_cast<std::int64_t>(std::llround(t_ns));
      ts.source_time_ns = ns;
      v = filter.check(ts, service::ReceiveTime{ns, ns});
    }
    if (v == service::Verdict::Accepted) {
      if (remove) kept.push_back(s);
    } else {
      rejected.push_back({i, s.time_s(), v});
    }
  }
  if (remove) station.samples = std::move(kept);
  return rejected;
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
      // The recording is the station (its rigid proxy in the step, as the live server's slot).
      poses.back().station = static_cast<int>(i);
      station_of_pose.push_back(static_cast<int>(i));
    }
    sim.step_at(t, poses, contacts, stats);  // time enters a viscoelastic body's step
    view.index = k;
    view.time_s = t;
    on_step(view);
  }
}

}  // namespace neurosim::replay
