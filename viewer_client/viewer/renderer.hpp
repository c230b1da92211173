// VTK scene of the viewer: deformed surfaces, tools coloured by force, and the
// resampled MRI, in one render window.
//   navigation: 2x2 viewports: 3D (surfaces, tool, the three slice planes) | axial
//                              coronal                                     | sagittal
//               the 2D views look along their slice axis, centred on the slice point.
//   observe:    one 3D viewport: volume rendering of the resampled MRI, surfaces, tools.
// Rigid meshes (the skull) are bone-coloured surfaces (shown / transparent / hidden) and bone
// contours on the slices; brain surfaces can be coloured by region (scene tissue).
// Units: metres in the scene; pixels for frames. VTK stays inside renderer.cpp.
#pragma once

#include "viewer_client/resample.hpp"
#include "viewer_client/viewer/options.hpp"
#include "viewer_client/viewer/state.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::viewer {

struct RenderOptions {
  Mode mode = Mode::Navigation;
  int width = 960, height = 720;  // unit px
  bool offscreen = true;
  bool overlay = true;
  double force_unit_n = 1.0;
  SkullMode skull = SkullMode::Shown;     // rigid meshes: opaque bone, translucent or hidden
  ColourMode colour = ColourMode::Plain;  // deformable surfaces: plain or by region
  // 3-D camera direction from the scene's centre (zero: from the right, anterior and above).
  Eigen::Vector3d view_from = Eigen::Vector3d::Zero();
  // Tool drawn as a sphere (tip) and a tube (shaft); the probe of the bundled scenes.
  double tip_radius_m = 0.002;
  double shaft_radius_m = 0.0015;
  double shaft_length_m = 0.08;  // drawn length (the scene's shaft is 0.15 m)
};

class SceneRenderer {
 public:
  explicit SceneRenderer(const RenderOptions& options);
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  // New meshes (topology): rebuilds the surface actors; the camera is placed from the meshes'
  // bounds the first time (a restarted server with the same scene keeps the view).
  void set_meshes(const ViewerState& state);
  // Deformed surfaces, tools and the status line.
  void update(const ViewerState& state, const std::string& status);
  // Image display range (grey levels), from the loaded MRI.
  void set_image_range(float low, float high);
  // Navigation: the three slices (axis 0, 1, 2) and the point they pass through; null: hide.
  void set_slices(const std::array<Slice, 3>* slices, const Eigen::Vector3d& centre_m);
  // Observe: the resampled volume; null: hide. Its octant beyond crop_centre_m (towards the
  // camera: +x, +y, +z) is cut away so the deformed interior shows on the cut faces.
  void set_volume(const ImageGrid* volume);
  void set_volume_crop(const Eigen::Vector3d& crop_centre_m);

  // How rigid meshes (the skull) are drawn, in the 3D view and as slice contours.
  void set_skull(SkullMode mode);
  SkullMode skull() const;

  void render();
  // PNG of the last render. Throws std::runtime_error naming the file on failure.
  void write_png(const std::string& path);
  // RGB bytes of the last render, rows bottom to top, width * height * 3.
  std::vector<std::uint8_t> capture();
  int width() const;
  int height() const;
  // 1 where a ball of radius_m around p projects, in any viewport (for image comparisons).
  std::vector<std::uint8_t> mask_around(const Eigen::Vector3d& p_m, double radius_m);
  // On screen: calls tick every period_s from the interactor's event loop until it returns false
  // or the window is closed. Key 'k' cycles the skull mode (shown, transparent, hidden).
  void run_interactive(const std::function<bool()>& tick, double period_s);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::viewer
