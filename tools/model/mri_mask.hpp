// Brain mask from a T1 volume: threshold (VTK), largest component, cavities filled.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <vtkImageData.h>
#include <vtkSmartPointer.h>

#include <Eigen/Core>

#include <array>
#include <string>

namespace neurosim::model {

using mesh::Vec3;

struct BrainMask {
  // Labels 1 (brain) / 0 (outside), unsigned char, in the reader's image coordinates
  // (voxel index x spacing + origin, unit mm): the coordinates the meshes are written in.
  vtkSmartPointer<vtkImageData> labels;
  // Image coordinates (mm) -> NIfTI world (sform, else qform; MNI mm for Colin27).
  Eigen::Matrix4d image_to_world{Eigen::Matrix4d::Identity()};
  bool has_world{false};
  std::array<int, 3> dims{};
  std::array<double, 3> spacing_mm{};
  std::array<double, 3> origin_mm{};
  long long voxels_inside{0};
};

// Reads the NIfTI file and builds the mask (voxels >= threshold). Throws std::runtime_error
// naming the file when it cannot be read or no voxel reaches the threshold.
BrainMask load_brain_mask(const std::string& path, double threshold);

Vec3 world_to_image(const BrainMask& mask, const Vec3& world_mm);
Vec3 image_to_world(const BrainMask& mask, const Vec3& image_mm);

// Keeps the largest face-connected component of the voxels != 0 (set to 1), clears the rest.
void keep_largest_component(unsigned char* voxels, const std::array<int, 3>& dims);

// Fills the holes of every axial slice (z = const): background voxels not connected, within
// their slice, to the slice's border become 1; returns how many were filled. A head's dark
// bone that the 3-D fill leaves open (it reaches the image's lower border through the neck,
// which the field of view cuts) is enclosed by the scalp in each axial slice.
long long fill_axial_slice_holes(unsigned char* voxels, const std::array<int, 3>& dims);

// Distance (mm) from p (image mm) to the centre of the nearest voxel outside the mask,
// searched up to max_mm (returns max_mm when none is that close).
double depth_in_mask_mm(const BrainMask& mask, const Vec3& p_image_mm, double max_mm);

}  // namespace neurosim::model
