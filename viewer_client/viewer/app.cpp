#include "viewer_client/viewer/app.hpp"

#include "common/clock.hpp"
#include "common/json.hpp"
#include "viewer_client/viewer/dds_client.hpp"
#include "viewer_client/viewer/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

namespace neurosim::viewer {

namespace {

using common::Clock;
using common::seconds_since;

// "tier NONLINEAR, equilibrium 12 Hz" ("tier LINEAR": nothing to update); then, once the server
// measures it, the strain: "tier LINEAR, strain 14 %". "" before the first SimStatus. Rates
// under 10 Hz keep one decimal.
std::string tier_text(const ServerStatusView& st) {
  if (!st.received) return {};
  std::ostringstream os;
  os << "tier " << st.tier;
  os.setf(std::ios::fixed);
  if (st.tier != "LINEAR") {
    os.precision(st.tier_update_rate_hz < 10 ? 1 : 0);
    os << ", equilibrium " << st.tier_update_rate_hz << " Hz";
  }
  if (st.max_strain >= 0) {
    os.precision(0);
    os << ", strain " << 100.0 * st.max_strain << " %";
  }
  return os.str();
}


std::string status_line(const ViewerOptions& o, const ViewerState& s, std::uint64_t frame,
                        bool has_image) {
  std::ostringstream os;
  os.setf(std::ios::fixed);
  os.precision(2);
  os << "neurosim-viewer " << to_string(o.mode) << "  frame " << frame << "  ";
  if (s.server_alive()) {
    os << "server live";
    // Only while live: a gone server's tier would pass for the running one. A line of its own:
    // the navigation mode's 3D viewport is a quarter of the frame and clips long lines.
    const std::string tier = tier_text(s.server_status());
    if (!tier.empty()) {
      // The error and its parts on two lines (the navigation viewport clips at ~60 characters).
      std::string error = error_text(s.server_status());
      const std::size_t parts = error.find(" (");
      if (parts != std::string::npos) error.replace(parts, 1, "\n  ");
      os << "\n" << tier << "\n" << error;
    }
  } else
    os << "WAITING FOR SERVER (showing the last state)";
  os << "\nmax |u| " << s.max_displacement_m() * 1e3 << " mm";
  for (const auto& [id, t] : s.tools())
    os << "   tool '" << id << "' |F| " << t.force_n.norm() << " N"
       << (t.in_contact ? " (contact)" : "");
  if (!has_image) os << "\nno MRI (see warnings): surfaces only";
  return os.str();
}

struct Totals {
  std::uint64_t frames = 0;
  double resample_ms = 0, render_ms = 0, max_resample_ms = 0;
  double samples = 0;  // resampled (slices or volume), summed over frames
};

void write_summary(const std::string& path, const ViewerOptions& o, const ViewerState& s,
                   const Totals& t, double run_s, std::ostream& log) {
  const ViewerCounters& c = s.counters();
  const double n = t.frames > 0 ? static_cast<double>(t.frames) : 1.0;
  common::Json j;
  j["mode"] = to_string(o.mode);
  j["frames"] = t.frames;
  j["run_s"] = run_s;
  j["resample_ms_mean"] = t.resample_ms / n;
  j["resample_ms_max"] = t.max_resample_ms;
  j["render_ms_mean"] = t.render_ms / n;
  j["samples_recomputed_mean"] = t.samples / n;
  j["meshes"] = s.meshes().size();
  j["topologies"] = c.topologies;
  j["deformations"] = c.deformations;
  j["deformations_waiting"] = c.deformations_waiting;
  j["tool_states"] = c.tool_states;
  j["contact_models"] = c.contact_models;
  j["malformed"] = c.malformed();
  j["server_seen"] = c.server_seen;
  j["server_lost"] = c.server_lost;
  // The newest SimStatus's tier and its equilibrium update rate (null: no SimStatus received).
  const ServerStatusView& st = s.server_status();
  j["statuses"] = c.statuses;
  j["server_tier"] = st.received ? common::Json(st.tier) : common::Json(nullptr);
  j["tier_update_rate_hz"] =
      st.received ? common::Json(st.tier_update_rate_hz) : common::Json(nullptr);
  j["max_strain"] =
      st.received && st.max_strain >= 0 ? common::Json(st.max_strain) : common::Json(nullptr);
  j["expected_force_error"] = st.received && st.expected_force_error >= 0
                                  ? common::Json(st.expected_force_error)
                                  : common::Json(nullptr);
  j["discretization_error_estimate"] = st.received && st.discretization_error_estimate >= 0
                                           ? common::Json(st.discretization_error_estimate)
                                           : common::Json(nullptr);
  j["total_error_estimate"] = st.received && st.total_error_estimate >= 0
                                  ? common::Json(st.total_error_estimate)
                                  : common::Json(nullptr);
  j["error_text"] = st.received ? common::Json(error_text(st)) : common::Json(nullptr);
  j["max_displacement_m"] = s.max_displacement_m();
  try {
    common::write_json(path, j);
  } catch (const std::exception& e) {
    log << "neurosim-viewer: warning: " << e.what() << " (the summary)\n";
  }
}

}  // namespace

int run_viewer(const ViewerOptions& o, std::ostream& log, const std::atomic<bool>* stop) {
  auto stopped = [&] { return stop != nullptr && stop->load(); };
  const char* display = std::getenv("DISPLAY");
  if (display == nullptr || *display == '\0') {
    log << "neurosim-viewer: no X display (DISPLAY is unset). VTK here renders through X, also "
           "offscreen: run under `xvfb-run -a neurosim-viewer ...`\n";
    return 2;
  }
  if (o.headless) {
    std::error_code ec;
    std::filesystem::create_directories(o.out_dir, ec);
    if (ec || !std::filesystem::is_directory(o.out_dir)) {
      log << "neurosim-viewer: " << o.out_dir << ": cannot create the frame folder ("
          << ec.message() << ")\n";
      return 1;
    }
  }
  const auto t_start = Clock::now();
  auto warn = [&log](const std::string& m) { log << "neurosim-viewer: warning: " << m << "\n"; };
  ViewerState state(warn);
  Totals totals;
  std::unique_ptr<DdsClient> dds;
  try {
    DdsClientOptions dopt;
    dopt.domain = o.domain;
    dopt.topic_prefix = o.topic_prefix;
    dds = std::make_unique<DdsClient>(dopt);
  } catch (const std::exception& e) {
    log << "neurosim-viewer: DDS: " << e.what() << "\n";
    return 1;
  }

  // Late joiner: MeshTopology is transient-local, so it arrives whenever the server runs.
  log << "neurosim-viewer: " << to_string(o.mode) << " mode, waiting up to " << o.wait_server_s
      << " s for MeshTopology (topic prefix '" << o.topic_prefix << "')\n";
  while (state.meshes().empty()) {
    if (stopped()) return 0;
    if (seconds_since(t_start) > o.wait_server_s) {
      log << "neurosim-viewer: no MeshTopology within " << o.wait_server_s
          << " s: is neurosim-server running on this DDS domain"
          << (o.topic_prefix.empty() ? "" : " with --topic-prefix " + o.topic_prefix) << "?\n";
      return 1;
    }
    dds->wait(0.1);
    dds->poll(state);
  }
  // The other meshes of the scene come in the same burst: give them a moment.
  for (int i = 0; i < 5; ++i) {
    dds->wait(0.05);
    dds->poll(state);
  }

  PipelineOptions popt;
  popt.render.mode = o.mode;
  popt.render.width = o.width;
  popt.render.height = o.height;
  popt.render.offscreen = o.headless;
  popt.render.overlay = o.overlay;
  popt.render.force_unit_n = o.force_unit_n;
  popt.render.skull = o.skull;
  popt.render.colour = o.colour;
  popt.render.view_from = Eigen::Vector3d(o.view_from[0], o.view_from[1], o.view_from[2]);
  popt.volume_step = o.volume_step;
  Pipeline pipeline(popt, warn);

  std::uint64_t seen_topologies = 0, seen_lost = 0, seen_seen = 0;
  std::string seen_tier;  // "server_id/tier" last logged
  auto log_events = [&] {
    const ViewerCounters& c = state.counters();
    const ServerStatusView& st = state.server_status();
    if (st.received && st.server_id + "/" + st.tier != seen_tier) {
      log << "neurosim-viewer: server '" << st.server_id << "' (scene '" << st.scene_name
          << "') runs tier " << st.tier << "\n";
      seen_tier = st.server_id + "/" + st.tier;
    }
    if (c.topologies != seen_topologies) {
      std::ostringstream os;
      for (const auto& m : state.meshes())
        os << " '" << m.id << "' (" << m.rest_m.size() << " vertices, " << m.tets.size()
           << " tetrahedra)";
      log << "neurosim-viewer: topology:" << os.str() << "; image '" << state.image_file() << "'\n";
      seen_topologies = c.topologies;
    }
    if (c.server_lost != seen_lost) {
      log << "neurosim-viewer: server lost: keeping the last state, waiting for it to return\n";
      seen_lost = c.server_lost;
    }
    if (c.server_seen != seen_seen) {
      log << "neurosim-viewer: server " << (c.server_seen > 1 ? "back" : "seen") << "\n";
      seen_seen = c.server_seen;
    }
  };

  const double period_s = 1.0 / o.fps;
  std::string error;
  // One frame: take what arrived, resample, render, write. False when done.
  auto tick = [&]() -> bool {
    if (stopped()) return false;
    if (o.duration_s > 0 && seconds_since(t_start) >= o.duration_s) return false;
    try {
      dds->poll(state);
      log_events();
      const FrameTiming ft =
          pipeline.frame(state, status_line(o, state, totals.frames, pipeline.has_image()));
      totals.resample_ms += ft.resample_ms;
      totals.max_resample_ms = std::max(totals.max_resample_ms, ft.resample_ms);
      totals.render_ms += ft.render_ms;
      totals.samples += static_cast<double>(ft.samples_recomputed);
      if (o.headless) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04llu.png",
                      static_cast<unsigned long long>(totals.frames));
        pipeline.renderer().write_png((std::filesystem::path(o.out_dir) / name).string());
      }
      ++totals.frames;
    } catch (const std::exception& e) {
      error = e.what();
      return false;
    }
    return !(o.frames > 0 && totals.frames >= static_cast<std::uint64_t>(o.frames));
  };

  if (o.headless) {
    auto next = Clock::now();
    while (tick()) {
      next += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
      const auto now = Clock::now();
      if (next < now) next = now;  // late: no catching up
      // Sleep in DDS-aware slices so a stop request is seen quickly.
      while (Clock::now() < next && !stopped()) {
        const double left = std::chrono::duration<double>(next - Clock::now()).count();
        std::this_thread::sleep_for(std::chrono::duration<double>(std::min(left, 0.05)));
      }
    }
  } else {
    pipeline.renderer().run_interactive(tick, period_s);
  }
  const double run_s = seconds_since(t_start);
  if (!o.summary_file.empty()) write_summary(o.summary_file, o, state, totals, run_s, log);
  const ViewerCounters& c = state.counters();
  log << "neurosim-viewer: " << totals.frames << " frames in " << run_s << " s"
      << (o.headless ? " written to " + o.out_dir : std::string()) << "; " << c.topologies
      << " topologies, " << c.deformations << " deformation frames, " << c.malformed()
      << " malformed samples ignored, server lost " << c.server_lost << " times";
  if (state.server_status().received)
    log << "; last SimStatus: " << tier_text(state.server_status()) << "; "
        << error_text(state.server_status());
  log << "\n";
  if (!error.empty()) {
    log << "neurosim-viewer: " << error << "\n";
    return 1;
  }
  return 0;
}

}  // namespace neurosim::viewer
