// Resampling of the MRI through the deformed meshes (docs/ARCHITECTURE.md "viewer_client").
//
// A sample point p of the deformed scene is mapped back to the rest configuration through the
// deformed tetrahedron that contains it: barycentric weights w of p in the deformed tetrahedron
// (x_i + u_i), rest point X = sum w_i x_i; the image is then read trilinearly at X. Points in no
// tetrahedron of any mesh are read at p itself (the tissue around the meshes does not move).
// Where meshes overlap (the artery inside the brain) the mesh of higher priority wins.
//
// Incremental: set_displacements() records which tetrahedra moved (by more than a tolerance)
// since the last update of each output; update_slice()/update_volume() recompute only the
// samples inside the bounding box of those tetrahedra (old and new positions), so a tool
// pressing on one spot costs one spot.
//
// Which tetrahedron: the point is searched in the meshes by decreasing priority (equal
// priorities: lower mesh index first). Within a mesh, of the deformed tetrahedra that contain
// the point (barycentric weights >= -1e-9, so points on shared faces are never lost), the one
// with the lowest index wins, a tetrahedron that kept its orientation before an inverted one;
// degenerate deformed tetrahedra (volume below 1e-6 of the rest volume) are skipped. The choice
// depends only on the point and the current displacements, never on the update history, so an
// incremental update gives the same values as a full one (exactly when no vertex moved by less
// than SamplerOptions::move_tolerance_m; otherwise within that motion). No input produces NaN:
// the rest point is a convex combination of rest vertices (weights >= -1e-9), or p itself.
//
// Lookup: a uniform grid per mesh over the deformed tetrahedra's bounding boxes, updated only
// for tetrahedra whose vertices changed; tetrahedra that leave the grid's domain (huge
// displacements) or span too many cells go to a short list that every lookup checks. Slices
// and the volume (a stack of z planes) are instead rasterized: each deformed tetrahedron that
// meets the plane marks the pixels it contains (each row clipped analytically, then the same
// exact test as the point search), the winner by the rule above is kept per pixel. The result
// equals sample() at every pixel, bit for bit.
//
// Units: metres inside (positions, displacements, spacing); image values are whatever the
// image holds (float). Pure Eigen + C++: no VTK, no DDS, so it is unit-testable on its own.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::viewer {

// A scalar volume on a regular grid: voxel (i, j, k) sits at origin_m + spacing_m .* (i, j, k);
// values are stored x fastest: values[i + dims[0] * (j + dims[1] * k)].
struct ImageGrid {
  std::array<int, 3> dims{0, 0, 0};
  Eigen::Vector3d origin_m{Eigen::Vector3d::Zero()};
  Eigen::Vector3d spacing_m{Eigen::Vector3d::Ones()};
  std::vector<float> values;
  // Set by DeformedVolumeSampler::update_volume on its output (see Slice::sampler_token);
  // unused on input images.
  std::uint64_t sampler_token = 0;

  std::size_t index(int i, int j, int k) const {
    return static_cast<std::size_t>(i) +
           static_cast<std::size_t>(dims[0]) *
               (static_cast<std::size_t>(j) + static_cast<std::size_t>(dims[1]) * k);
  }
  // Throws std::invalid_argument when dims, spacing or the value count are inconsistent, or a
  // spacing/origin component is not finite and positive (spacing) / finite (origin), or a
  // value is not finite (the voxel is named).
  void validate() const;
};

// Trilinear interpolation at p (m); outside the grid (beyond the outermost voxel centres) the
// value is `outside`. Non-finite p gives `outside`. A point within 1e-9 voxel of a voxel centre
// gives that voxel's value exactly (so resampling the image on its own grid is bit-exact).
// Throws std::invalid_argument when the value count does not match dims (see validate()).
float sample_trilinear(const ImageGrid& image, const Eigen::Vector3d& p_m, float outside = 0.0F);

// One mesh as the viewer knows it (from MeshTopology): rest vertices (m) and tetrahedra.
struct MeshGeometry {
  std::string id;
  std::vector<Eigen::Vector3d> rest_m;
  std::vector<std::array<int, 4>> tets;
  int priority = 0;  // higher wins where meshes overlap
};

// An axis-aligned slice through the deformed scene: axis 0 = sagittal (constant x),
// 1 = coronal (constant y), 2 = axial (constant z). The in-plane axes are the two others in
// increasing order (u = first, v = second); pixel (a, b) sits at
// origin_m + a * spacing_m(u) e_u + b * spacing_m(v) e_v, with the slice coordinate
// position_m along the slice axis. values[a + width * b].
struct Slice {
  int axis = 2;
  double position_m = 0.0;
  int width = 0;
  int height = 0;
  Eigen::Vector3d origin_m{Eigen::Vector3d::Zero()};  // pixel (0, 0), its slice component unused
  Eigen::Vector2d spacing_m{Eigen::Vector2d::Ones()};
  std::vector<float> values;
  // Set by DeformedVolumeSampler::update_slice to tell its own outputs from new ones at a
  // reused address; leave it alone (a copy or a fresh Slice is recomputed in full).
  std::uint64_t sampler_token = 0;
};

// Slice of the image's own grid through the voxel plane nearest position_m (same pixel spacing
// and extent as the image in the two in-plane axes), values not yet computed (zeros). A
// position beyond the image snaps to its first/last voxel plane. Throws std::invalid_argument
// on an axis other than 0-2, a non-finite position or inconsistent image dims/spacing/origin/
// value count (the values themselves are not scanned: this is cheap).
Slice make_image_slice(const ImageGrid& image, int axis, double position_m);

// Options of DeformedVolumeSampler (defaults suit a 1 mm MRI and meshes of ~1-7 mm elements).
struct SamplerOptions {
  // A vertex counts as moved when |u - u_reported| exceeds this (u_reported: its displacement
  // when it last counted as moved), unit m. Smaller changes still update the point map at once
  // but do not by themselves mark samples for recomputation, so an incrementally updated output
  // lags the exact one by at most about this much displacement. 0: every change counts.
  double move_tolerance_m{1e-5};
  // Image value where the rest point falls outside the image.
  float outside_value{0.0F};
  // Grid cell edge of each mesh's search grid = this x the mean tetrahedron bounding-box edge.
  double grid_cell_factor{1.0};
};

// Where a deformed-space point was found (DeformedVolumeSampler::locate).
struct Location {
  int mesh = -1;  // -1: in no tetrahedron (rest point = the point itself)
  int tet = -1;
  Eigen::Vector4d weights{Eigen::Vector4d::Zero()};  // barycentric in the deformed tetrahedron
  bool inverted = false;                             // the deformed tetrahedron is inverted
  Eigen::Vector3d rest_m{Eigen::Vector3d::Zero()};   // the rest point (unit m)
};

struct ResampleStats {
  std::size_t samples_recomputed = 0;  // in the last update
  std::size_t samples_total = 0;
  std::size_t moved_tets = 0;  // tetrahedra that moved since that output's last update
};

class DeformedVolumeSampler {
 public:
  // Copies the image and meshes; builds the search structure over the rest (undeformed) meshes.
  // Throws std::invalid_argument naming the mesh and tetrahedron on an out-of-range vertex id or
  // a non-finite vertex, and on an invalid image.
  DeformedVolumeSampler(ImageGrid image, std::vector<MeshGeometry> meshes,
                        const SamplerOptions& options = SamplerOptions{});
  ~DeformedVolumeSampler();
  DeformedVolumeSampler(DeformedVolumeSampler&&) noexcept;
  DeformedVolumeSampler& operator=(DeformedVolumeSampler&&) noexcept;

  std::size_t mesh_count() const;
  const ImageGrid& image() const;
  const MeshGeometry& mesh(std::size_t index) const;
  // Index of the mesh with this id (the Deformation topic's key), -1 when there is none.
  int find_mesh(const std::string& id) const;

  // New displacements of mesh `mesh` (3 per vertex, x y z, m; the Deformation topic's layout).
  // count is the number of floats, 3 x the vertex count (Deformation::displacement_m.size()).
  // Throws std::invalid_argument on a mesh index out of range, a wrong size or a non-finite
  // component (names mesh and vertex); the previous displacements are then kept.
  void set_displacements(std::size_t mesh, const float* u_m, std::size_t count);
  // The same with one vector per vertex (unit m).
  void set_displacements(std::size_t mesh, const std::vector<Eigen::Vector3d>& u_m);
  // Current displacement of every vertex of mesh `mesh` (unit m).
  const std::vector<Eigen::Vector3d>& displacements(std::size_t mesh) const;

  // Point map deformed -> rest (see the file comment). Returns p itself outside every mesh
  // (and for a non-finite p).
  Eigen::Vector3d to_rest(const Eigen::Vector3d& p_m) const;
  // The same, saying which mesh and tetrahedron (see Location).
  Location locate(const Eigen::Vector3d& p_m) const;
  // The image value at deformed-space point p.
  float sample(const Eigen::Vector3d& p_m) const;

  // Recompute the slice: all of it the first time (or when its axis/position/extent changed),
  // afterwards only the pixels in the region whose tetrahedra moved since its last update.
  // Each output is tracked separately by its address: keep Slice objects alive between calls.
  // Throws std::invalid_argument on a bad slice (axis not 0-2, non-positive size or spacing,
  // non-finite origin or position).
  ResampleStats update_slice(Slice& slice);

  // The whole deformed volume on the image grid (for volume rendering), incrementally as above.
  // `deformed` takes the image's dims, origin and spacing on its first update.
  ResampleStats update_volume(ImageGrid& deformed);

  // Stop tracking an output (before destroying it, so a new object at the same address starts
  // with a full recompute; one is also forced when its values buffer changed).
  void forget(const Slice& slice);
  void forget(const ImageGrid& deformed);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::viewer
