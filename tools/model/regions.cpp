// AAL labels sampled at tetrahedron centroids (nearest labelled voxel within a few mm).
#include "tools/model/regions.hpp"

#include "tools/model/mri_mask.hpp"

#include "common/nifti.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <tuple>

namespace neurosim::model {

const char* region_name(int label) {
  switch (label) {
    case kCerebrum:
      return "cerebrum";
    case kCerebellum:
      return "cerebellum";
    case kOther:
      return "other";
    default:
      return "unknown";
  }
}

std::vector<int> label_regions(const mesh::TetMesh& brain, const BrainMask& grid,
                               const AtlasOptions& o) {
  if (!(o.search_mm >= 0.0) || !std::isfinite(o.search_mm))
    throw std::invalid_argument("atlas: search radius must be finite and >= 0 mm");
  const nifti::Volume atlas = nifti::read(o.path);
  Eigen::Matrix4d sform = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      sform(r, c) = atlas.image_to_world[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];
  if (atlas.dims != grid.dims || atlas.spacing != grid.spacing_mm ||
      atlas.origin != grid.origin_mm || atlas.has_world != grid.has_world ||
      !sform.isApprox(grid.image_to_world)) {
    throw std::runtime_error(o.path + ": grid or sform differs from the brain image's");
  }
  const std::vector<float> values = atlas.float_values();
  const auto& d = grid.dims;
  auto class_of = [&](long long i) {
    const float v = values[static_cast<std::size_t>(i)];
    if (v <= 0.0f) return 0;
    const int a = static_cast<int>(std::lround(v));
    if (a >= o.cerebellum_first && a <= o.cerebellum_last) return static_cast<int>(kCerebellum);
    return a < o.cerebellum_first ? static_cast<int>(kCerebrum) : static_cast<int>(kOther);
  };
  // Voxel offsets within the search radius, nearest first (ties in a fixed order).
  std::vector<std::tuple<double, int, int, int>> offsets;
  const int r = static_cast<int>(std::ceil(o.search_mm / grid.spacing_mm[0]));
  for (int k = -r; k <= r; ++k)
    for (int j = -r; j <= r; ++j)
      for (int i = -r; i <= r; ++i) {
        const double dd =
            std::hypot(i * grid.spacing_mm[0], j * grid.spacing_mm[1], k * grid.spacing_mm[2]);
        if (dd <= o.search_mm) offsets.emplace_back(dd, i, j, k);
      }
  std::sort(offsets.begin(), offsets.end());
  std::vector<int> labels(brain.num_tets(), kOther);
  for (std::size_t t = 0; t < brain.num_tets(); ++t) {
    const auto& tet = brain.tets()[t];
    const Vec3 c = 1e3 * 0.25 *
                   (brain.vertices()[tet[0]] + brain.vertices()[tet[1]] + brain.vertices()[tet[2]] +
                    brain.vertices()[tet[3]]);  // image mm
    int ijk[3];
    for (int a = 0; a < 3; ++a)
      ijk[a] = static_cast<int>(std::lround((c[a] - grid.origin_mm[a]) / grid.spacing_mm[a]));
    for (const auto& [dist, di, dj, dk] : offsets) {
      const int x = ijk[0] + di, y = ijk[1] + dj, z = ijk[2] + dk;
      if (x < 0 || y < 0 || z < 0 || x >= d[0] || y >= d[1] || z >= d[2]) continue;
      const int cls =
          class_of(x + static_cast<long long>(d[0]) * (y + static_cast<long long>(d[1]) * z));
      if (cls != 0) {
        labels[t] = cls;
        break;
      }
    }
  }
  return labels;
}

RegionStats region_stats(const mesh::TetMesh& brain, const std::vector<int>& labels,
                         const BrainMask& grid) {
  if (labels.size() != brain.num_tets())
    throw std::invalid_argument("region_stats: one label per tetrahedron needed");
  RegionStats s;
  std::array<Vec3, 4> moment{};
  for (auto& m : moment) m.setZero();
  for (std::size_t t = 0; t < brain.num_tets(); ++t) {
    const int l = labels[t];
    if (l < 1 || l > 3) throw std::invalid_argument("region_stats: label " + std::to_string(l));
    const auto& tet = brain.tets()[t];
    const double v = brain.tet_volume(static_cast<int>(t)) * 1e9;  // mm^3
    const Vec3 c = 1e3 * 0.25 *
                   (brain.vertices()[tet[0]] + brain.vertices()[tet[1]] + brain.vertices()[tet[2]] +
                    brain.vertices()[tet[3]]);
    s.volume_ml[l] += v * 1e-3;
    moment[l] += v * c;
    ++s.tets[l];
  }
  for (int l = 1; l <= 3; ++l) {
    s.centroid_world_mm[l] = s.volume_ml[l] > 0.0
                                 ? image_to_world(grid, moment[l] / (s.volume_ml[l] * 1e3))
                                 : Vec3::Zero();
  }
  return s;
}

}  // namespace neurosim::model
