// State -> resampled MRI -> VTK scene, once per frame. Owns the resampler and the
// renderer; rebuilds them when the topology changes (a new server, a late join), loads the MRI
// the topology names (once per file) and keeps rendering without it when it is missing.
#pragma once

#include "viewer_client/resample.hpp"
#include "viewer_client/viewer/renderer.hpp"
#include "viewer_client/viewer/state.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace neurosim::viewer {

struct PipelineOptions {
  RenderOptions render;
  int volume_step = 2;  // observe: volume resampled every this many voxels
  // A vertex counts as moved for the incremental resampling once its displacement changed by
  // more than this since it last counted (SamplerOptions::move_tolerance_m), unit m. A tenth of
  // the 1 mm MRI voxel: the slow far-field creep of the soft brain does not redo whole slices
  // every frame, and the picture lags the exact resampling by at most this much motion.
  double move_tolerance_m = 1e-4;
};

struct FrameTiming {
  double resample_ms = 0;  // slices (navigation) or volume (observe) this frame, unit ms
  double render_ms = 0;    // VTK render, unit ms
  std::size_t samples_recomputed = 0;
};

class Pipeline {
 public:
  using Warn = std::function<void(const std::string&)>;
  Pipeline(const PipelineOptions& options, Warn warn);
  ~Pipeline();

  // Brings the scene up to date with `state` (rebuild on a new topology, new displacements
  // into the resampler, slices through the primary tool tip or the volume) and renders it.
  FrameTiming frame(const ViewerState& state, const std::string& status);
  SceneRenderer& renderer() { return *renderer_; }
  bool has_image() const { return image_loaded_; }
  // The point the slices pass through (the primary tool tip, else the centre of the meshes).
  Eigen::Vector3d slice_centre(const ViewerState& state) const;
  const std::array<Slice, 3>& slices() const { return slices_; }

 private:
  void rebuild(const ViewerState& state);
  PipelineOptions opt_;
  Warn warn_;
  std::unique_ptr<SceneRenderer> renderer_;
  std::unique_ptr<DeformedVolumeSampler> sampler_;
  std::string image_file_;  // loaded (or failed) image
  bool image_loaded_ = false;
  ImageGrid image_;  // as read (navigation) or downsampled (observe)
  std::uint64_t generation_ = ~std::uint64_t{0};
  std::vector<std::uint64_t> u_versions_;  // per sampler mesh, pushed into the sampler
  std::vector<std::string> sampler_meshes_;
  std::array<Slice, 3> slices_;
  std::array<int, 3> slice_plane_{-1, -1, -1};  // voxel plane each slice is on
  ImageGrid volume_;
  bool volume_started_ = false;
};

}  // namespace neurosim::viewer
