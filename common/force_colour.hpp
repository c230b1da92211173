// The paper's tool colour by force: with f = |F| / force_unit_n (F in N),
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)), each in [0, 1]; a force
// that is not finite shows as f = 1 (red). One rule for the viewer and the web observer (the
// page's web/page/src/colour.js computes the same in the browser). Header-only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

namespace neurosim::common {

inline std::array<double, 3> force_colour(double force_n, double force_unit_n = 1.0) {
  const double f = std::isfinite(force_n) ? std::abs(force_n) / force_unit_n : 1.0;
  return {std::min(0.2 + f, 1.0), std::max(0.2 - f, 0.0), std::max(0.2 - f, 0.0)};
}

}  // namespace neurosim::common
