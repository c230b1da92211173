// The skull as a rigid obstacle: a closed, smooth triangle surface of the bone shell around the
// brain (inner and outer table), cut open where the scene has a craniotomy.
#pragma once

#include "server/mesh/tet_mesh.hpp"
#include "tools/model/mesh3.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace neurosim::model {

struct BrainMask;  // mri_mask.hpp (VTK)

// A craniotomy in image coordinates (mm): the solid cylinder of radius_mm around the axis through
// center_mm along `axis` (unit, out of the head), within half_length_mm of center_mm along it.
struct CutCylinder {
  Vec3 center_mm{Vec3::Zero()};
  Vec3 axis{Vec3::UnitZ()};
  double radius_mm{15.0};
  double half_length_mm{25.0};
  bool contains(const Vec3& p_mm) const;
};

struct SkullOptions {
  // Colin27 T1 with the head (same grid as ch2bet), Debian package mricron-data.
  std::string head_path{"/usr/share/mricron/templates/ch2.nii.gz"};
  double head_threshold{30.0};  // T1 intensity (0..254): voxels >= it, filled, are the head
  // The bone shell: from csf_gap_mm to csf_gap_mm + thickness_mm outside the brain mask's
  // surface. CSF (subarachnoid space) ~2-3 mm; adult cranial bone ~6-7 mm.
  double csf_gap_mm{3.0};
  double thickness_mm{6.5};
  double smoothing_sigma_mm{1.5};  // Gaussian on the shell's indicator before meshing, unit mm
  // Iso 0.5 of the smoothed indicator; facets within 1 mm of it keep the inner table clear of
  // the brain surface (gap >= 1 mm of the 3 mm CSF gap).
  GraySurfaceOptions surface{/*iso_value=*/0.5, /*facet_size_mm=*/8.0,
                             /*facet_distance_mm=*/1.0};
  std::vector<CutCylinder> openings;
};

struct SkullResult {
  SurfaceOutput surface;             // image mm, outward
  double head_volume_ml{0.0};        // the head mask
  long long head_filled_in_slices{0};  // head voxels added by the axial-slice hole fill
  double shell_volume_ml{0.0};       // the bone shell voxels meshed (after clipping and openings)
  long long clipped_by_head{0};      // shell voxels outside the head mask (dropped)
  long long removed_by_openings{0};  // shell voxels inside an opening (dropped)
  long long dropped_fragments{0};    // shell voxels not in its largest piece (dropped)
  double seconds_mask{0.0};          // head mask, distance, shell, smoothing, unit s
  double seconds_mesh{0.0};          // CGAL surface meshing, unit s
};

// Builds the skull surface around `brain` (its grid must equal the head image's; throws
// std::runtime_error naming the file otherwise).
SkullResult build_skull(const BrainMask& brain, const SkullOptions& options);

// Exact Euclidean distance (mm) from every voxel centre to the nearest voxel centre with
// mask != 0 (0 on the mask; +infinity when the mask is empty). x fastest, then y, then z.
std::vector<float> distance_from_mask_mm(const unsigned char* mask, const std::array<int, 3>& dims,
                                         const std::array<double, 3>& spacing_mm);

}  // namespace neurosim::model
