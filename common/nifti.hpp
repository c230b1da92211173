// The one NIfTI reader (.nii / .nii.gz, VTK's vtkNIFTIImageReader) for the model builder, the
// viewer and the benchmarks. Target neurosim::nifti (built when VTK is found).
#pragma once

#include <vtkImageData.h>
#include <vtkSmartPointer.h>

#include <array>
#include <string>
#include <vector>

namespace neurosim::nifti {

struct Volume {
  // One scalar per voxel, as stored in the file; VTK image coordinates (voxel index times spacing
  // plus origin), in the file's unit (mm for MRI).
  vtkSmartPointer<vtkImageData> image;
  std::array<int, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{0, 0, 0};
  std::array<double, 3> origin{0, 0, 0};
  // VTK image coordinates to NIfTI world coordinates: the sform matrix, else the qform one
  // (has_world false when the file has neither).
  bool has_world = false;
  std::array<std::array<double, 4>, 4> image_to_world{};

  // The voxel values as float, x fastest then y then z.
  std::vector<float> float_values() const;
};

// Reads a single-component NIfTI volume. Throws std::runtime_error naming the file when it is
// missing, not NIfTI, unreadable or not a scalar volume.
Volume read(const std::string& path);

}  // namespace neurosim::nifti
