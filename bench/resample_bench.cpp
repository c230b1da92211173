// resample_bench: resampling of the real MRI through the deformed brain/artery model.
//   resample_bench [--csv] [--frames N] [--volume-runs N] [--scene FILE] [--sigma-mm S]
//                  [--step-mm D] [--push-mm A] [--cell-factor F]
// A tool pushes a local patch of the brain surface: a Gaussian displacement bump (sigma S mm,
// default 5) along the inward normal at a point of the lateral surface, growing by D mm per
// frame (default 0.05, a 1.5 mm/s push seen at 30 Hz) up to A mm (default 4) and back; the
// artery (embedded in the brain) takes the same field. Rows:
//   slices3_full         the three orthogonal slices through the tool tip, made anew
//                        (make_image_slice) and computed in full
//   slices3_incremental  the same slices after each frame's push (update_slice x 3)
//   set_displacements    both meshes' new displacements (search structure update)
//   frame_incremental    set_displacements + slices3_incremental: the viewer's work per frame
//   volume_full          the whole deformed volume on the MRI grid
//   volume_incremental   the volume after each frame's push
// p50/p99 in ms over the runs (wall, and CPU time of the thread: the machine may be shared);
// samples = mean samples recomputed per run (of samples_total);
// moved_tets = mean tetrahedra reported moved per run. One thread. --csv prints only the table.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "server/scene/compile.hpp"
#include "viewer_client/resample.hpp"
#include "viewer_client/viewer/image_io.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace nv = neurosim::viewer;
using neurosim::common::Clock;
using Eigen::Vector3d;

namespace {

using neurosim::common::ms_since;
using neurosim::common::percentile;
// CPU time of this thread (the machine is shared: wall time includes waiting).
using neurosim::common::thread_cpu_ms;

// Wall and CPU time of one timed section.
struct Timer {
  Clock::time_point wall = Clock::now();
  double cpu = thread_cpu_ms();
};

struct Row {
  explicit Row(std::string n) : name(std::move(n)) {}
  std::string name;
  std::vector<double> ms, cpu_ms;
  double samples = 0, total = 0, moved = 0;
  void add(const Timer& t) {
    ms.push_back(ms_since(t.wall));
    cpu_ms.push_back(thread_cpu_ms() - t.cpu);
  }
  void add(const Timer& t, const Row& before) {  // this frame's time plus `before`'s last
    ms.push_back(ms_since(t.wall) + before.ms.back());
    cpu_ms.push_back(thread_cpu_ms() - t.cpu + before.cpu_ms.back());
  }
};

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  int frames = 160, volume_runs = 10;
  double sigma_mm = 5.0, step_mm = 0.05, push_mm = 4.0;
  nv::SamplerOptions options;
  std::string scene_path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_artery.scene";
  neurosim::cli::Parser cli("resample_bench",
                            "The MRI resampled through the deformed brain/artery model.");
  cli.add_flag("--csv", csv, "print only the table");
  cli.add_option("--frames", frames, "frames of the push (at least 1)")->capture_default_str();
  cli.add_option("--volume-runs", volume_runs, "volume runs (at least 1)")->capture_default_str();
  cli.add_option("--scene", scene_path, "scene file")->capture_default_str();
  cli.add_option("--sigma-mm", sigma_mm, "bump width S, unit mm")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--step-mm", step_mm, "push per frame D, unit mm")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--push-mm", push_mm, "deepest push A, unit mm")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--cell-factor", options.grid_cell_factor, "search grid cell factor")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  frames = std::max(1, frames);
  volume_runs = std::max(1, volume_runs);

  // The scene's meshes (built as the server builds them) and its MRI.
  const auto t_load = Clock::now();
  const neurosim::scene::Scene scene = neurosim::scene::read_scene(scene_path);
  const std::filesystem::path scene_dir = std::filesystem::path(scene_path).parent_path();
  std::vector<nv::MeshGeometry> meshes;
  std::vector<neurosim::scene::LoadedMesh> loaded;
  for (const auto& entry : scene.meshes()) {
    loaded.push_back(neurosim::scene::load_mesh(entry, scene_dir, scene_path));
    nv::MeshGeometry g;
    g.id = loaded.back().id;
    g.rest_m = loaded.back().mesh.vertices();
    g.tets = loaded.back().mesh.tets();
    g.priority = loaded.back().priority;
    meshes.push_back(std::move(g));
  }
  const int brain = neurosim::scene::find_mesh(scene, "brain");
  if (brain < 0 || !scene.has_image()) {
    std::cerr << scene_path << ": needs a mesh 'brain' and an image\n";
    return 1;
  }
  nv::ImageGrid image = nv::load_nifti(scene.image().file(), scene.image().file_unit_m());
  const double load_ms = ms_since(t_load);

  // Tool: the brain surface vertex farthest along +x near the middle of the lateral surface
  // (the scene's prescribed push region), pushed inward along -x.
  const auto& bm = loaded[brain].mesh;
  Vector3d target(0.0, 0.115, 0.079);
  int tip_vertex = -1;
  double best = -1e300;
  for (int v : bm.surface_vertices()) {
    const Vector3d& x = bm.vertices()[v];
    const double score = x.x() - 4.0 * std::hypot(x.y() - target.y(), x.z() - target.z());
    if (score > best) best = score, tip_vertex = v;
  }
  const Vector3d tip = bm.vertices()[tip_vertex];
  const Vector3d dir(-1.0, 0.0, 0.0);
  const double sigma = sigma_mm * 1e-3;
  const auto bump = [&](const std::vector<Vector3d>& rest, double amp_m) {
    std::vector<float> u(3 * rest.size(), 0.0F);
    for (std::size_t v = 0; v < rest.size(); ++v) {
      const double w = std::exp(-(rest[v] - tip).squaredNorm() / (2 * sigma * sigma));
      for (int a = 0; a < 3; ++a) u[3 * v + a] = static_cast<float>(amp_m * w * dir[a]);
    }
    return u;
  };

  const auto t_build = Clock::now();
  nv::DeformedVolumeSampler sampler(image, meshes, options);
  const double build_ms = ms_since(t_build);
  std::size_t tets = 0;
  for (const auto& m : meshes) tets += m.tets.size();
  if (!csv) {
    std::printf("scene %s: %zu meshes, %zu tetrahedra; MRI %d x %d x %d, %.2f mm\n",
                scene_path.c_str(), meshes.size(), tets, image.dims[0], image.dims[1],
                image.dims[2], image.spacing_m[0] * 1e3);
    std::printf(
        "load %.0f ms, sampler build %.1f ms; tool tip at (%.1f, %.1f, %.1f) mm, "
        "bump sigma %.1f mm, step %.3f mm/frame up to %.1f mm\n",
        load_ms, build_ms, tip.x() * 1e3, tip.y() * 1e3, tip.z() * 1e3, sigma_mm, step_mm, push_mm);
  }

  // Amplitude of frame f: up and down a triangle wave.
  const int half = std::max(1, static_cast<int>(std::lround(push_mm / step_mm)));
  const auto amplitude = [&](int f) {
    const int k = f % (2 * half);
    return 1e-3 * step_mm * (k <= half ? k : 2 * half - k);
  };
  const auto set_frame = [&](int f) {
    for (std::size_t m = 0; m < meshes.size(); ++m) {
      const auto u = bump(meshes[m].rest_m, amplitude(f));
      sampler.set_displacements(m, u.data(), u.size());
    }
  };

  std::vector<nv::Slice> slices;
  for (int axis = 0; axis < 3; ++axis)
    slices.push_back(nv::make_image_slice(image, axis, tip[axis]));

  Row full{"slices3_full"}, inc{"slices3_incremental"}, setd{"set_displacements"};
  Row frame{"frame_incremental"};
  Row vfull{"volume_full"}, vinc{"volume_incremental"};

  // Full three-slice resample at the deformed state of each frame.
  for (int f = 0; f < frames; ++f) {
    set_frame(f);
    double samples = 0, total = 0;
    const Timer t0;
    for (nv::Slice& s : slices) {
      s = nv::make_image_slice(image, s.axis, s.position_m);  // as the viewer does on a new plane
      const nv::ResampleStats st = sampler.update_slice(s);
      samples += st.samples_recomputed;
      total += st.samples_total;
    }
    full.add(t0);
    full.samples += samples / frames;
    full.total = total;
  }

  // Incremental: one frame's push, then the three slices.
  set_frame(0);
  for (nv::Slice& s : slices) sampler.update_slice(s);
  for (int f = 1; f <= frames; ++f) {
    const Timer t_set;
    set_frame(f);
    setd.add(t_set);
    double samples = 0, total = 0, moved = 0;
    const Timer t0;
    for (nv::Slice& s : slices) {
      const nv::ResampleStats st = sampler.update_slice(s);
      samples += st.samples_recomputed;
      total += st.samples_total;
      moved = std::max(moved, static_cast<double>(st.moved_tets));
    }
    inc.add(t0);
    frame.add(t0, setd);
    inc.samples += samples / frames;
    inc.total = total;
    inc.moved += moved / frames;
  }

  // Volume, full and incremental.
  nv::ImageGrid volume;
  for (int r = 0; r < volume_runs; ++r) {
    set_frame(r * 7 + 3);
    sampler.forget(volume);
    const Timer t0;
    const nv::ResampleStats st = sampler.update_volume(volume);
    vfull.add(t0);
    vfull.samples += static_cast<double>(st.samples_recomputed) / volume_runs;
    vfull.total = static_cast<double>(st.samples_total);
  }
  set_frame(0);
  sampler.update_volume(volume);
  const int vframes = std::max(volume_runs, 20);
  for (int f = 1; f <= vframes; ++f) {
    set_frame(f);
    const Timer t0;
    const nv::ResampleStats st = sampler.update_volume(volume);
    vinc.add(t0);
    vinc.samples += static_cast<double>(st.samples_recomputed) / vframes;
    vinc.total = static_cast<double>(st.samples_total);
    vinc.moved += static_cast<double>(st.moved_tets) / vframes;
  }

  // Sanity: no NaN anywhere, and the push changed the slices.
  std::size_t bad = 0;
  for (const auto& s : slices)
    for (float v : s.values) bad += !std::isfinite(v);
  for (float v : volume.values) bad += !std::isfinite(v);
  if (bad) {
    std::cerr << "resample_bench: " << bad << " non-finite samples\n";
    return 1;
  }

  frame.samples = inc.samples, frame.total = inc.total, frame.moved = inc.moved;
  std::printf(
      "case,runs,p50_ms,p99_ms,cpu_p50_ms,cpu_p99_ms,samples_recomputed,samples_total,"
      "moved_tets\n");
  for (const Row* r : {&full, &inc, &setd, &frame, &vfull, &vinc}) {
    std::printf("%s,%zu,%.3f,%.3f,%.3f,%.3f,%.0f,%.0f,%.0f\n", r->name.c_str(), r->ms.size(),
                percentile(r->ms, 0.5), percentile(r->ms, 0.99), percentile(r->cpu_ms, 0.5),
                percentile(r->cpu_ms, 0.99), r->samples, r->total, r->moved);
  }
  if (!csv) {
    std::printf("target: slices3 <= 10 ms per frame on one core\n");
  }
  return 0;
}
