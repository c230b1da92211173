// Skull: shell between two distances from the brain mask, clipped to the head, cut open, smoothed,
// then its iso-surface meshed by CGAL (mesh3.cpp).
#include "tools/model/skull.hpp"

#include "tools/model/mri_mask.hpp"

#include "common/clock.hpp"

#include <vtkImageData.h>
#include <vtkImageGaussianSmooth.h>
#include <vtkSmartPointer.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace neurosim::model {
namespace {

// Felzenszwalb & Huttenlocher (2012), "Distance transforms of sampled functions": the lower
// envelope of parabolas, one line at a time; f holds squared distances (mm^2), step the spacing.
void edt_line(std::vector<double>& f, double step, std::vector<double>& d, std::vector<int>& v,
              std::vector<double>& z) {
  const int n = static_cast<int>(f.size());
  const double inf = std::numeric_limits<double>::infinity();
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (!std::isfinite(f[q])) continue;
    const double xq = q * step;
    double s = -inf;
    while (k >= 0) {
      const double xv = v[k] * step;
      s = ((f[q] + xq * xq) - (f[v[k]] + xv * xv)) / (2.0 * (xq - xv));
      if (s > z[k]) break;
      --k;
    }
    ++k;
    v[k] = q;
    z[k] = k == 0 ? -inf : s;
    z[k + 1] = inf;
  }
  if (k < 0) return;  // no finite value on this line
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < q * step) ++j;
    const double dx = (q - v[j]) * step;
    d[q] = dx * dx + f[v[j]];
  }
  f = d;
}

}  // namespace

bool CutCylinder::contains(const Vec3& p) const {
  const Vec3 r = p - center_mm;
  const double along = r.dot(axis);
  return std::abs(along) <= half_length_mm && (r - along * axis).norm() < radius_mm;
}

std::vector<float> distance_from_mask_mm(const unsigned char* mask, const std::array<int, 3>& d,
                                         const std::array<double, 3>& spacing) {
  const long long nx = d[0], ny = d[1], nz = d[2], n = nx * ny * nz;
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> g(static_cast<std::size_t>(n));
  for (long long i = 0; i < n; ++i) g[i] = mask[i] ? 0.0 : inf;
  const long long stride[3] = {1, nx, nx * ny};
  for (int axis = 0; axis < 3; ++axis) {
    const int len = d[axis];
    std::vector<double> f(len), out(len, inf), z(len + 1);
    std::vector<int> v(len);
    // Every line along `axis`: start indices over the other two axes.
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    for (int j = 0; j < d[a2]; ++j) {
      for (int i = 0; i < d[a1]; ++i) {
        const long long start = i * stride[a1] + j * stride[a2];
        for (int q = 0; q < len; ++q) f[q] = g[start + q * stride[axis]];
        std::fill(out.begin(), out.end(), inf);
        edt_line(f, spacing[axis], out, v, z);
        for (int q = 0; q < len; ++q) g[start + q * stride[axis]] = f[q];
      }
    }
  }
  std::vector<float> dist(static_cast<std::size_t>(n));
  for (long long i = 0; i < n; ++i) dist[i] = static_cast<float>(std::sqrt(g[i]));
  return dist;
}

SkullResult build_skull(const BrainMask& brain, const SkullOptions& o) {
  for (double v : {o.csf_gap_mm, o.thickness_mm, o.smoothing_sigma_mm}) {
    if (!(v > 0.0) || !std::isfinite(v))
      throw std::invalid_argument(
          "skull: CSF gap, thickness and smoothing must be finite and > 0 mm");
  }
  for (const auto& c : o.openings) {
    if (!c.center_mm.allFinite() || !(std::abs(c.axis.norm() - 1.0) < 1e-9) ||
        !(c.radius_mm > 0.0) || !(c.half_length_mm > 0.0))
      throw std::invalid_argument(
          "skull: an opening needs a finite centre, a unit axis and a "
          "radius and half length > 0");
  }
  SkullResult r;
  const auto t0 = common::Clock::now();
  // The head: T1 above the threshold, one piece, cavities (the dark bone, sinuses) filled.
  // The 3-D fill leaves the occipital bone open where it reaches the neck at the field of view's
  // lower border; each axial slice closes it (the scalp rings it).
  BrainMask head = load_brain_mask(o.head_path, o.head_threshold);
  if (head.dims != brain.dims || head.spacing_mm != brain.spacing_mm ||
      head.origin_mm != brain.origin_mm || !head.image_to_world.isApprox(brain.image_to_world)) {
    throw std::runtime_error(o.head_path + ": grid or sform differs from the brain image's");
  }
  const double voxel_ml = brain.spacing_mm[0] * brain.spacing_mm[1] * brain.spacing_mm[2] * 1e-3;
  r.head_filled_in_slices = fill_axial_slice_holes(
      static_cast<unsigned char*>(head.labels->GetScalarPointer()), head.dims);
  head.voxels_inside += r.head_filled_in_slices;
  r.head_volume_ml = head.voxels_inside * voxel_ml;

  // Distances are from voxel centres; the mask's surface lies half a voxel outside them.
  const auto* b = static_cast<const unsigned char*>(brain.labels->GetScalarPointer());
  const auto* h = static_cast<const unsigned char*>(head.labels->GetScalarPointer());
  const std::vector<float> dist = distance_from_mask_mm(b, brain.dims, brain.spacing_mm);
  const double half_voxel = 0.5 * brain.spacing_mm[0];
  const double inner = o.csf_gap_mm + half_voxel, outer = inner + o.thickness_mm;
  const auto& d = brain.dims;
  const long long n = static_cast<long long>(d[0]) * d[1] * d[2];
  std::vector<unsigned char> shell(static_cast<std::size_t>(n), 0);
  for (long long i = 0; i < n; ++i) {
    if (dist[i] < inner || dist[i] > outer) continue;
    if (!h[i]) {
      ++r.clipped_by_head;
      continue;
    }
    const long long x = i % d[0], y = (i / d[0]) % d[1],
                    z = i / (static_cast<long long>(d[0]) * d[1]);
    const Vec3 p(brain.origin_mm[0] + x * brain.spacing_mm[0],
                 brain.origin_mm[1] + y * brain.spacing_mm[1],
                 brain.origin_mm[2] + z * brain.spacing_mm[2]);
    bool cut = false;
    for (const auto& c : o.openings) cut = cut || c.contains(p);
    if (cut) {
      ++r.removed_by_openings;
      continue;
    }
    shell[i] = 1;
  }
  // One piece: crumbs left by the head clipping would be separate little surfaces.
  const long long before = std::count(shell.begin(), shell.end(), 1);
  keep_largest_component(shell.data(), d);
  const long long kept = std::count(shell.begin(), shell.end(), 1);
  r.dropped_fragments = before - kept;
  r.shell_volume_ml = kept * voxel_ml;
  if (kept == 0) throw std::runtime_error("skull: the bone shell is empty");

  // Smooth indicator: its 0.5 level is a smooth surface near the shell's voxel boundary.
  auto indicator = vtkSmartPointer<vtkImageData>::New();
  indicator->CopyStructure(brain.labels);
  indicator->AllocateScalars(VTK_FLOAT, 1);
  auto* f = static_cast<float*>(indicator->GetScalarPointer());
  for (long long i = 0; i < n; ++i) f[i] = shell[i] ? 1.0f : 0.0f;
  auto smooth = vtkSmartPointer<vtkImageGaussianSmooth>::New();
  smooth->SetInputData(indicator);
  smooth->SetDimensionality(3);
  smooth->SetStandardDeviations(o.smoothing_sigma_mm / brain.spacing_mm[0],
                                o.smoothing_sigma_mm / brain.spacing_mm[1],
                                o.smoothing_sigma_mm / brain.spacing_mm[2]);
  smooth->SetRadiusFactors(3.0, 3.0, 3.0);
  smooth->Update();
  r.seconds_mask = common::seconds_since(t0);

  const auto t1 = common::Clock::now();
  r.surface = mesh_gray_surface(smooth->GetOutput(), o.surface);
  r.seconds_mesh = common::seconds_since(t1);
  return r;
}

}  // namespace neurosim::model
