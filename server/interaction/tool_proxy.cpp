#include "server/interaction/tool_proxy.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace neurosim::interaction {

ToolProxy::ToolProxy(const RigidObstacle& obstacle, const ToolProxyOptions& options)
    : obstacle_(&obstacle), options_(options), scratch_(obstacle.make_scratch()) {
  if (!(options.reach_m > 0.0 && std::isfinite(options.reach_m)))
    throw std::invalid_argument("ToolProxyOptions::reach_m must be > 0");
  if (!(options.max_reach_m >= options.reach_m && std::isfinite(options.max_reach_m)))
    throw std::invalid_argument("ToolProxyOptions::max_reach_m must be >= reach_m");
  if (options.projection_iterations < 1)
    throw std::invalid_argument("ToolProxyOptions::projection_iterations must be >= 1");
}

void ToolProxy::constrain(const ToolShape& shape, ToolPose& pose, ObstaclePlanes& planes) {
  const mesh::Vec3 raw = pose.tip_m;
  // First pose (or after reset): free if the tip sphere is outside the bone. That check is a
  // brute-force winding number (O(triangles)), paid once per station session, not per step.
  if (!has_free_ && !obstacle_->inside(raw) &&
      obstacle_->closest(raw).distance_m >= shape.tip_radius_m) {
    has_free_ = true;
    free_tip_m_ = raw;
  }
  // The planes cover the device's travel since the last step (at least reach_m, at most
  // max_reach_m) around the free tip; the proxy moves at most that far from it below.
  const double travel = has_last_raw_ ? (raw - last_raw_m_).norm() : 0.0;
  last_raw_m_ = raw;
  has_last_raw_ = true;
  const double reach = std::min(std::max(options_.reach_m, travel), options_.max_reach_m);
  ObstacleQuery q;
  q.free_known = has_free_;
  q.free_tip_m = has_free_ ? free_tip_m_ : raw;
  q.tip_m = raw;
  q.axis = pose.axis;
  q.shape = shape;
  q.reach_m = reach;
  obstacle_->query(q, scratch_, planes);
  mesh::Vec3 x = raw;
  // Euclidean projection onto the intersection of the half-spaces n . (x - p) >= 0 (Dykstra):
  // the god-object, the free point closest to the device.
  const int m = planes.count;
  if (m > 0) {
    auto violation = [&](const mesh::Vec3& y, int i) {
      const auto& p = planes.planes[static_cast<std::size_t>(i)];
      return -p.normal.dot(y - p.point_m);
    };
    bool any = false;
    for (int i = 0; i < m; ++i) any = any || violation(x, i) > 0.0;
    if (any) {
      for (int i = 0; i < m; ++i) dykstra_[static_cast<std::size_t>(i)].setZero();
      for (int it = 0; it < options_.projection_iterations; ++it) {
        double worst = 0.0;
        for (int i = 0; i < m; ++i) {
          const auto& p = planes.planes[static_cast<std::size_t>(i)];
          auto& y = dykstra_[static_cast<std::size_t>(i)];
          const mesh::Vec3 z = x + y;
          const double v = -p.normal.dot(z - p.point_m);
          const mesh::Vec3 proj = v > 0.0 ? mesh::Vec3(z + v * p.normal) : z;
          y = z - proj;
          x = proj;
        }
        for (int i = 0; i < m; ++i) worst = std::max(worst, violation(x, i));
        if (worst <= options_.tolerance_m) break;
      }
      // Dykstra's last iterate may miss a plane by a little: finish with plain projections.
      for (int sweep = 0; sweep < 8; ++sweep) {
        double worst = 0.0;
        for (int i = 0; i < m; ++i) {
          const double v = violation(x, i);
          if (v > 0.0) x += v * planes.planes[static_cast<std::size_t>(i)].normal;
          worst = std::max(worst, v);
        }
        if (worst <= options_.tolerance_m) break;
      }
      // No point satisfies every plane (a gap narrower than the tool): stay where it was free.
      double worst = 0.0;
      for (int i = 0; i < m; ++i) worst = std::max(worst, violation(x, i));
      if (has_free_ && worst > 1e3 * options_.tolerance_m) x = free_tip_m_;
    }
  }
  // Only what the planes cover: at most `reach` from the free tip, along the segment to the
  // projected point (both on the free side of every plane, so the segment is too).
  if (has_free_) {
    const double len = (x - free_tip_m_).norm();
    if (len > reach) x = free_tip_m_ + (x - free_tip_m_) * (reach / len);
    free_tip_m_ = x;
  }
  pose.tip_m = x;
}

}  // namespace neurosim::interaction
