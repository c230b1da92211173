// The MRI the topology names, as a resampling grid (VTK's NIfTI reader), and grid helpers.
#pragma once

#include "viewer_client/resample.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace neurosim::viewer {

// Reads a NIfTI volume (.nii / .nii.gz) with neurosim::nifti (common/nifti.hpp): VTK image
// coordinates (voxel index times spacing, origin 0, as the scene's meshes use) times unit_m give
// metres. Throws std::runtime_error naming the file when it is missing or unreadable.
ImageGrid load_nifti(const std::string& path, double unit_m);

// Every step-th voxel (a coarser grid over the same extent), for volume rendering.
ImageGrid downsample(const ImageGrid& image, int step);

// Writes RGB bytes (rows bottom to top, as SceneRenderer::capture) as a PNG. Throws
// std::runtime_error naming the file on failure.
void write_png_rgb(const std::string& path, int width, int height,
                   const std::vector<std::uint8_t>& rgb);

// Display window (low, high) of an image: 0 .. the 99.5th percentile of its non-zero values.
std::pair<float, float> display_range(const ImageGrid& image);

}  // namespace neurosim::viewer
