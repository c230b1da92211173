#include "server/interaction/tool_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace neurosim::interaction {

PointGrid::PointGrid(const std::vector<mesh::Vec3>& points_m, double cell_m)
    : count_(static_cast<int>(points_m.size())) {
  if (!(cell_m > 0.0) || !std::isfinite(cell_m))
    throw std::invalid_argument("PointGrid: cell size must be > 0");
  if (points_m.empty()) return;
  mesh::Vec3 lo = points_m.front(), hi = points_m.front();
  for (const auto& p : points_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  // At most ~64 cells per axis: a surface grid, the query cost is in the per-node test.
  const double extent = (hi - lo).maxCoeff();
  cell_ = std::max(cell_m, extent / 64.0);
  origin_ = lo;
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::max(1, static_cast<int>(std::floor((hi[a] - lo[a]) / cell_)) + 1);
  const int cells = dims_[0] * dims_[1] * dims_[2];
  std::vector<int> cell_of(points_m.size());
  offsets_.assign(cells + 1, 0);
  for (std::size_t i = 0; i < points_m.size(); ++i) {
    int idx[3];
    for (int a = 0; a < 3; ++a)
      idx[a] = std::clamp(static_cast<int>(std::floor((points_m[i][a] - lo[a]) / cell_)), 0,
                          dims_[a] - 1);
    cell_of[i] = (idx[2] * dims_[1] + idx[1]) * dims_[0] + idx[0];
    ++offsets_[cell_of[i] + 1];
  }
  for (int c = 0; c < cells; ++c) offsets_[c + 1] += offsets_[c];
  items_.resize(points_m.size());
  std::vector<int> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t i = 0; i < points_m.size(); ++i)
    items_[fill[cell_of[i]]++] = static_cast<int>(i);
}

void PointGrid::query(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const {
  if (count_ == 0) return;
  int a0[3], a1[3];
  for (int a = 0; a < 3; ++a) {
    const double l = (lo[a] - origin_[a]) / cell_, h = (hi[a] - origin_[a]) / cell_;
    if (h < 0.0 || l >= dims_[a]) return;
    a0[a] = std::max(0, static_cast<int>(std::floor(l)));
    a1[a] = std::min(dims_[a] - 1, static_cast<int>(std::floor(h)));
  }
  for (int z = a0[2]; z <= a1[2]; ++z)
    for (int y = a0[1]; y <= a1[1]; ++y)
      for (int x = a0[0]; x <= a1[0]; ++x) {
        const int c = (z * dims_[1] + y) * dims_[0] + x;
        for (int k = offsets_[c]; k < offsets_[c + 1]; ++k) out.push_back(items_[k]);
      }
}

}  // namespace neurosim::interaction
