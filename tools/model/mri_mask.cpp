// Brain mask from the T1 volume: neurosim::nifti reads, VTK thresholds, a flood fill cleans up.
#include "tools/model/mri_mask.hpp"

#include "common/nifti.hpp"

#include <vtkImageThreshold.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <vector>

namespace neurosim::model {
namespace {

// Face-connected components of voxels equal to `value`, grown by breadth-first search: with
// from_border, every component touching the volume's border (an axis of size 1, a slice, has no
// border along it); otherwise only the largest. Returns 1 for the kept voxels, 0 elsewhere.
std::vector<unsigned char> components(const unsigned char* v, const std::array<int, 3>& d,
                                      unsigned char value, bool from_border) {
  const long long nx = d[0], ny = d[1], nz = d[2], n = nx * ny * nz;
  std::vector<int> label(static_cast<std::size_t>(n), -1);
  std::vector<long long> queue;
  std::vector<long long> sizes;
  auto grow = [&](long long start, int id) {
    long long count = 0;
    queue.assign(1, start);
    label[start] = id;
    for (std::size_t q = 0; q < queue.size(); ++q) {
      const long long i = queue[q];
      ++count;
      const long long x = i % nx, y = (i / nx) % ny, z = i / (nx * ny);
      const long long nb[6][2] = {{x > 0, i - 1},       {x + 1 < nx, i + 1},
                                  {y > 0, i - nx},      {y + 1 < ny, i + nx},
                                  {z > 0, i - nx * ny}, {z + 1 < nz, i + nx * ny}};
      for (const auto& [ok, j] : nb) {
        if (ok && label[j] < 0 && v[j] == value) {
          label[j] = id;
          queue.push_back(j);
        }
      }
    }
    return count;
  };
  for (long long i = 0; i < n; ++i) {
    if (v[i] != value || label[i] >= 0) continue;
    if (from_border) {
      const long long x = i % nx, y = (i / nx) % ny, z = i / (nx * ny);
      const bool border = x == 0 || x == nx - 1 || y == 0 || y == ny - 1 ||
                          (nz > 1 && (z == 0 || z == nz - 1));
      if (!border) continue;
      grow(i, 0);  // every border-connected component is kept
    } else {
      sizes.push_back(grow(i, static_cast<int>(sizes.size())));
    }
  }
  const int keep =
      from_border ? 0
                  : static_cast<int>(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
  std::vector<unsigned char> out(static_cast<std::size_t>(n), 0);
  for (long long i = 0; i < n; ++i) out[i] = label[i] == keep ? 1 : 0;
  return out;
}

unsigned char* voxels(vtkImageData* image) {
  return static_cast<unsigned char*>(image->GetScalarPointer());
}

}  // namespace

BrainMask load_brain_mask(const std::string& path, double threshold) {
  if (!std::isfinite(threshold)) throw std::invalid_argument(path + ": mask threshold not finite");
  if (!std::filesystem::is_regular_file(path)) {
    throw std::runtime_error(path + ": no such MRI file (Debian package mricron-data)");
  }
  const nifti::Volume mri = nifti::read(path);
  vtkImageData* t1 = mri.image;

  BrainMask mask;
  mask.dims = mri.dims;
  mask.spacing_mm = mri.spacing;
  mask.origin_mm = mri.origin;
  // The sform/qform matrix maps the reader's data coordinates to NIfTI world coordinates.
  mask.has_world = mri.has_world;
  if (mri.has_world)
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        mask.image_to_world(r, c) =
            mri.image_to_world[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];

  // T1 >= threshold: brain tissue and the CSF inside the brain-extracted volume.
  auto thr = vtkSmartPointer<vtkImageThreshold>::New();
  thr->SetInputData(t1);
  thr->ThresholdByUpper(threshold);
  thr->SetInValue(1);
  thr->SetOutValue(0);
  thr->ReplaceInOn();
  thr->ReplaceOutOn();
  thr->SetOutputScalarTypeToUnsignedChar();
  thr->Update();

  // One piece (drop stray voxels), then fill cavities: outside is the background connected to
  // the image border, everything else is brain.
  auto brain = vtkSmartPointer<vtkImageData>::New();
  brain->DeepCopy(thr->GetOutput());
  unsigned char* b = voxels(brain);
  const long long n = brain->GetNumberOfPoints();
  const auto largest = components(b, mask.dims, 1, false);
  std::copy(largest.begin(), largest.end(), b);
  const auto outside = components(b, mask.dims, 0, true);
  for (long long i = 0; i < n; ++i) {
    b[i] = outside[i] ? 0 : 1;
    mask.voxels_inside += b[i];
  }
  if (mask.voxels_inside == 0) {
    throw std::runtime_error(path + ": no voxel reaches the mask threshold " +
                             std::to_string(threshold));
  }
  mask.labels = brain;
  return mask;
}

Vec3 world_to_image(const BrainMask& mask, const Vec3& world_mm) {
  if (!mask.has_world) return world_mm;
  const Eigen::Vector4d p = mask.image_to_world.inverse() * world_mm.homogeneous();
  return p.head<3>();
}

Vec3 image_to_world(const BrainMask& mask, const Vec3& image_mm) {
  if (!mask.has_world) return image_mm;
  return (mask.image_to_world * image_mm.homogeneous()).head<3>();
}

void keep_largest_component(unsigned char* voxels, const std::array<int, 3>& dims) {
  const long long n = static_cast<long long>(dims[0]) * dims[1] * dims[2];
  long long any = 0;
  for (long long i = 0; i < n; ++i) any += voxels[i] = voxels[i] ? 1 : 0;
  if (any == 0) return;
  const auto largest = components(voxels, dims, 1, false);
  std::copy(largest.begin(), largest.end(), voxels);
}

long long fill_axial_slice_holes(unsigned char* voxels, const std::array<int, 3>& dims) {
  const std::array<int, 3> slice{dims[0], dims[1], 1};
  const long long per_slice = static_cast<long long>(dims[0]) * dims[1];
  long long filled = 0;
  for (long long z = 0; z < dims[2]; ++z) {
    unsigned char* v = voxels + z * per_slice;
    const auto outside = components(v, slice, 0, true);
    for (long long i = 0; i < per_slice; ++i) {
      if (!v[i] && !outside[i]) {
        v[i] = 1;
        ++filled;
      }
    }
  }
  return filled;
}

double depth_in_mask_mm(const BrainMask& mask, const Vec3& p, double max_mm) {
  const auto& d = mask.dims;
  const unsigned char* v = static_cast<const unsigned char*>(mask.labels->GetScalarPointer());
  int lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = static_cast<int>(std::floor((p[a] - max_mm - mask.origin_mm[a]) / mask.spacing_mm[a]));
    hi[a] = static_cast<int>(std::ceil((p[a] + max_mm - mask.origin_mm[a]) / mask.spacing_mm[a]));
  }
  double best2 = max_mm * max_mm;
  for (int k = lo[2]; k <= hi[2]; ++k) {
    for (int j = lo[1]; j <= hi[1]; ++j) {
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const Vec3 c(mask.origin_mm[0] + i * mask.spacing_mm[0],
                     mask.origin_mm[1] + j * mask.spacing_mm[1],
                     mask.origin_mm[2] + k * mask.spacing_mm[2]);
        const double dist2 = (c - p).squaredNorm();
        if (dist2 >= best2) continue;
        const bool in_image = i >= 0 && j >= 0 && k >= 0 && i < d[0] && j < d[1] && k < d[2];
        if (!in_image ||
            v[i + static_cast<long long>(d[0]) * (j + static_cast<long long>(d[1]) * k)] == 0) {
          best2 = dist2;
        }
      }
    }
  }
  return std::sqrt(best2);
}

}  // namespace neurosim::model
