// The shaft axis of a tool pose: the tool frame's +z rotated into the scene frame by the
// orientation q = (w, x, y, z) (ToolState.orientation, docs/ARCHITECTURE.md "From a tool pose to
// a force and back", step 3). One formula for the server, the replay, the viewer and the web
// observer. Header-only.
#pragma once

#include <array>
#include <cmath>

namespace neurosim::common {

// For a unit quaternion q: the third column of its rotation matrix, not renormalised (the
// server steps exactly this vector).
inline std::array<double, 3> rotated_z(const double q[4]) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  return {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)};
}

// For any quaternion: the rotation of q / |q| (the formula above is quadratic in q, so a q that
// is not unit is normalised first, not the result), at unit length; +z when q is zero or not
// finite (what the viewers draw for a pose they cannot read).
inline std::array<double, 3> shaft_axis(const double q[4]) {
  const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(qn > 1e-150) || !std::isfinite(qn)) return {0.0, 0.0, 1.0};
  const double u[4] = {q[0] / qn, q[1] / qn, q[2] / qn, q[3] / qn};
  const std::array<double, 3> a = rotated_z(u);
  const double n = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(n > 1e-12) || !std::isfinite(n)) return {0.0, 0.0, 1.0};
  return {a[0] / n, a[1] / n, a[2] / n};
}

}  // namespace neurosim::common
