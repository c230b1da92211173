#include "viewer_client/viewer/pipeline.hpp"

#include "common/clock.hpp"
#include "viewer_client/viewer/image_io.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace neurosim::viewer {

using common::ms_since;

Pipeline::Pipeline(const PipelineOptions& options, Warn warn)
    : opt_(options),
      warn_(std::move(warn)),
      renderer_(std::make_unique<SceneRenderer>(options.render)) {}

Pipeline::~Pipeline() = default;

Eigen::Vector3d Pipeline::slice_centre(const ViewerState& state) const {
  if (const ToolView* t = state.primary_tool()) return t->tip_m;
  const auto [lo, hi] = state.bounds_m();
  return 0.5 * (lo + hi);
}

void Pipeline::rebuild(const ViewerState& state) {
  renderer_->set_meshes(state);
  sampler_.reset();
  sampler_meshes_.clear();
  u_versions_.clear();
  slice_plane_ = {-1, -1, -1};
  volume_started_ = false;

  // The MRI: loaded once per file; a missing one is a warning (surfaces still render).
  const std::string file = state.image_file();
  if (file != image_file_) {
    image_file_ = file;
    image_loaded_ = false;
    if (file.empty()) {
      if (warn_) warn_("the topology names no volume image: surfaces only, no MRI");
    } else {
      try {
        ImageGrid im = load_nifti(file, state.image_unit_m());
        const auto [lo, hi] = display_range(im);
        renderer_->set_image_range(lo, hi);
        image_ =
            opt_.render.mode == Mode::Observe ? downsample(im, opt_.volume_step) : std::move(im);
        image_loaded_ = true;
      } catch (const std::exception& e) {
        if (warn_) warn_(std::string(e.what()) + ": rendering without the MRI");
      }
    }
  }
  if (!image_loaded_) {
    renderer_->set_slices(nullptr, slice_centre(state));
    renderer_->set_volume(nullptr);
    return;
  }
  std::vector<MeshGeometry> meshes;
  for (const MeshState& m : state.meshes()) {
    if (m.rigid) continue;  // no tetrahedra, never deformed: not part of the resampling
    MeshGeometry g;
    g.id = m.id;
    g.rest_m = m.rest_m;
    g.tets = m.tets;
    g.priority = m.priority;
    meshes.push_back(std::move(g));
    sampler_meshes_.push_back(m.id);
  }
  try {
    SamplerOptions so;
    so.move_tolerance_m = opt_.move_tolerance_m;
    sampler_ = std::make_unique<DeformedVolumeSampler>(image_, std::move(meshes), so);
  } catch (const std::exception& e) {
    if (warn_) warn_(std::string("cannot resample the MRI through these meshes: ") + e.what());
    sampler_meshes_.clear();
  }
  u_versions_.assign(sampler_meshes_.size(), ~std::uint64_t{0});
  if (opt_.render.mode == Mode::Observe) volume_ = image_;  // same grid; values recomputed
}

FrameTiming Pipeline::frame(const ViewerState& state, const std::string& status) {
  FrameTiming timing;
  if (state.topology_generation() != generation_) {
    generation_ = state.topology_generation();
    rebuild(state);
  }
  const auto t0 = std::chrono::steady_clock::now();
  if (sampler_) {
    // New displacements into the resampler (it tracks which tetrahedra moved).
    for (std::size_t i = 0; i < sampler_meshes_.size(); ++i) {
      const MeshState* m = state.mesh(sampler_meshes_[i]);
      if (m == nullptr || m->u_version == u_versions_[i]) continue;
      try {
        sampler_->set_displacements(i, m->u_m.data(), m->u_m.size());
      } catch (const std::exception& e) {
        if (warn_) warn_(std::string("resampler refused the displacements: ") + e.what());
      }
      u_versions_[i] = m->u_version;
    }
    const Eigen::Vector3d c = slice_centre(state);
    if (opt_.render.mode == Mode::Navigation) {
      for (int axis = 0; axis < 3; ++axis) {
        const auto a = static_cast<std::size_t>(axis);
        const double rel = (c[axis] - image_.origin_m[axis]) / image_.spacing_m[axis];
        const int plane = std::clamp(static_cast<int>(std::lround(std::isfinite(rel) ? rel : 0.0)),
                                     0, image_.dims[a] - 1);
        if (plane != slice_plane_[a]) {
          slices_[a] = make_image_slice(image_, axis, c[axis]);
          slice_plane_[a] = plane;
        }
        const ResampleStats st = sampler_->update_slice(slices_[a]);
        timing.samples_recomputed += st.samples_recomputed;
      }
      timing.resample_ms = ms_since(t0);
      renderer_->set_slices(&slices_, c);
    } else {
      const ResampleStats st = sampler_->update_volume(volume_);
      timing.samples_recomputed = st.samples_recomputed;
      timing.resample_ms = ms_since(t0);
      // The volume is re-uploaded only when something in it changed.
      if (st.samples_recomputed > 0 || !volume_started_) renderer_->set_volume(&volume_);
      volume_started_ = true;
      // Cut through the tool tip (x: the middle of the meshes, so the cut is deep).
      const auto [lo, hi] = state.bounds_m();
      renderer_->set_volume_crop(Eigen::Vector3d(0.5 * (lo.x() + hi.x()), c.y(), c.z()));
    }
  } else if (opt_.render.mode == Mode::Navigation) {
    renderer_->set_slices(nullptr, slice_centre(state));
  }
  renderer_->update(state, status);
  const auto t1 = std::chrono::steady_clock::now();
  renderer_->render();
  timing.render_ms = ms_since(t1);
  return timing;
}

}  // namespace neurosim::viewer
