// viewer_bench: frame rate of neurosim-viewer's pipeline on this machine (software
// OpenGL under Xvfb), no DDS: the brain/artery scene's meshes are loaded directly and a tool
// dents the brain (a smooth 10 mm wide dent, depth varying frame to frame so every frame
// resamples), with the MRI the scene names.
//   xvfb-run -a build/bin/viewer_bench [--scene FILE] [--frames N] [--size WxH] [--csv]
// Prints per mode: frames per second (resample + render), mean slice/volume resample time per
// frame, mean render time, and the first (full) resample.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/scene/compile.hpp"
#include "viewer_client/viewer/pipeline.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>

namespace nv = neurosim::viewer;

namespace {

struct Result {
  std::string mode;
  int frames = 0;
  double fps = 0, resample_ms = 0, render_ms = 0, first_resample_ms = 0, max_resample_ms = 0;
  double samples = 0;
};

// The scene as the viewer would receive it.
nv::ViewerState load_state(const std::string& scene_path) {
  const auto scene = neurosim::scene::read_scene(scene_path);
  const auto dir = std::filesystem::path(scene_path).parent_path();
  nv::ViewerState s;
  for (const auto& entry : scene.meshes()) {
    const auto loaded = neurosim::scene::load_mesh(entry, dir, scene_path);
    nv::MeshState m;
    m.id = loaded.id;
    m.rest_m = loaded.mesh.vertices();
    m.tets = loaded.mesh.tets();
    m.surface = loaded.mesh.surface();
    m.priority = loaded.priority;
    std::string image = scene.image().file();
    if (!image.empty() && std::filesystem::path(image).is_relative())
      image = (dir / image).string();
    m.image_file = image;
    m.image_unit_m = scene.image().file_unit_m();
    s.set_mesh(std::move(m));
  }
  return s;
}

// Dent of the given depth around p along -n (Gaussian, sigma 10 mm) on every mesh.
void dent(nv::ViewerState& s, const Eigen::Vector3d& p, const Eigen::Vector3d& n, double depth_m) {
  for (const auto& m : s.meshes()) {
    std::vector<float> u(3 * m.rest_m.size());
    for (std::size_t i = 0; i < m.rest_m.size(); ++i) {
      const double r2 = (m.rest_m[i] - p).squaredNorm();
      const Eigen::Vector3d d = -depth_m * std::exp(-r2 / (2 * 0.01 * 0.01)) * n;
      for (int k = 0; k < 3; ++k) u[3 * i + static_cast<std::size_t>(k)] = static_cast<float>(d[k]);
    }
    s.set_displacements(m.id, std::move(u));
  }
}

// move_tool: the tip follows the dent (the slices through it move too, so slices whose plane
// changes are recomputed in full); otherwise the tip stays put and only the dent changes.
Result run(nv::Mode mode, nv::ViewerState state, int frames, int w, int h, bool move_tool) {
  // The demo's press point on the right lateral surface and its outward normal.
  const Eigen::Vector3d p(0.1605, 0.1125, 0.0787);
  const Eigen::Vector3d n = Eigen::Vector3d(0.963, 0.176, 0.202).normalized();
  nv::PipelineOptions po;
  po.render.mode = mode;
  po.render.width = w;
  po.render.height = h;
  po.render.offscreen = true;
  nv::Pipeline pipe(
      po, [](const std::string& m) { std::cerr << "viewer_bench: warning: " << m << "\n"; });
  nv::ToolView tool;
  tool.station = "bench";
  tool.axis = n;
  tool.has_pose = true;
  tool.in_contact = true;
  Result r;
  r.mode = std::string(nv::to_string(mode)) + (move_tool ? "" : "/fixed");
  // First frame: full resample (and image load, excluded from the rates).
  dent(state, p, n, 0.004);
  tool.tip_m = p + (0.002 - 0.004) * n;
  state.set_tool(tool);
  const nv::FrameTiming first = pipe.frame(state, "viewer_bench");
  r.first_resample_ms = first.resample_ms;
  const auto t0 = std::chrono::steady_clock::now();
  for (int f = 0; f < frames; ++f) {
    const double depth = 0.004 + 0.002 * std::sin(0.7 * (f + 1));
    dent(state, p, n, depth);
    if (move_tool) tool.tip_m = p + (0.002 - depth) * n;
    tool.force_n = 0.05 * depth / 0.001 * n;
    state.set_tool(tool);
    const nv::FrameTiming t = pipe.frame(state, "viewer_bench");
    r.resample_ms += t.resample_ms;
    r.max_resample_ms = std::max(r.max_resample_ms, t.resample_ms);
    r.render_ms += t.render_ms;
    r.samples += static_cast<double>(t.samples_recomputed);
  }
  const double s = neurosim::common::seconds_since(t0);
  r.frames = frames;
  r.fps = frames / s;
  r.resample_ms /= frames;
  r.render_ms /= frames;
  r.samples /= frames;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_artery.scene";
  int frames = 40, w = 960, h = 720;
  bool csv = false;
  std::string size = "960x720";
  neurosim::cli::Parser cli("viewer_bench",
                            "neurosim-viewer's frame rates offscreen (run under xvfb-run -a).");
  cli.add_option("--scene", scene, "scene file")->capture_default_str();
  cli.add_option("--frames", frames, "frames per case (> 0)")
      ->check(neurosim::cli::in_range(1, 1e9))
      ->capture_default_str();
  cli.add_option("--size", size, "frame size WxH (at least 64x64)")->capture_default_str();
  cli.add_flag("--csv", csv, "print CSV");
  cli.check([&] {
    char x = 0;
    char rest = 0;
    if (std::sscanf(size.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || x != 'x' || w < 64 ||
        h < 64)
      throw neurosim::cli::UsageError("--size: expected WxH of at least 64x64, got '" + size + "'");
  });
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (std::getenv("DISPLAY") == nullptr) {
    std::cerr << "viewer_bench: no X display: run under xvfb-run -a\n";
    return 2;
  }
  try {
    const nv::ViewerState state = load_state(scene);
    const Result nav = run(nv::Mode::Navigation, state, frames, w, h, true);
    const Result fixed = run(nv::Mode::Navigation, state, frames, w, h, false);
    const Result obs = run(nv::Mode::Observe, state, std::max(3, frames / 8), w, h, true);
    if (csv) {
      std::printf(
          "mode,frames,fps,resample_ms_mean,resample_ms_max,first_resample_ms,render_ms_mean,"
          "samples_per_frame\n");
      for (const Result* r : {&nav, &fixed, &obs})
        std::printf("%s,%d,%.2f,%.2f,%.2f,%.1f,%.1f,%.0f\n", r->mode.c_str(), r->frames, r->fps,
                    r->resample_ms, r->max_resample_ms, r->first_resample_ms, r->render_ms,
                    r->samples);
    } else {
      std::printf("viewer_bench: %s, %dx%d, software OpenGL (%s)\n", scene.c_str(), w, h,
                  std::getenv("DISPLAY"));
      std::printf("%-17s %6s %7s %16s %15s %17s %14s %12s\n", "mode", "frames", "fps",
                  "resample ms/frm", "resample max ms", "first (full) ms", "render ms/frm",
                  "samples/frm");
      for (const Result* r : {&nav, &fixed, &obs})
        std::printf("%-17s %6d %7.2f %16.2f %15.2f %17.1f %14.1f %12.0f\n", r->mode.c_str(),
                    r->frames, r->fps, r->resample_ms, r->max_resample_ms, r->first_resample_ms,
                    r->render_ms, r->samples);
      std::printf(
          "navigation: three 1 mm slices through the tool tip, which follows the dent (a slice "
          "whose plane changes is recomputed in full);\nnavigation/fixed: the tip stays, only the "
          "dent changes; observe: the whole volume every 2nd voxel\n");
    }
  } catch (const std::exception& e) {
    std::cerr << "viewer_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
