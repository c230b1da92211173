// The paper's tool colour by force: with f = |F| / force_unit_n (F in N),
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)), each in [0, 1]; a force
// that is not finite shows as f = 1 (red). One rule for the viewer, the web observer and its
// page: the numbers are written once, in kForceColourRule below; the build writes them into the
// page's JavaScript (web/colour_rule_js.cpp generates force_colour_rule.js, which
// web/page/src/colour.js applies the same way). Header-only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

namespace neurosim::common {

// Each channel k is clamp(offset[k] + slope[k] * f, 0, 1), f = |F| / force unit (dimensionless).
struct ForceColourRule {
  std::array<double, 3> offset;  // R, G, B at f = 0 (dimensionless, 0..1)
  std::array<double, 3> slope;   // change per unit of f (dimensionless)
  double not_finite_f;           // the f a non-finite force is shown with
};

inline constexpr ForceColourRule kForceColourRule{{0.2, 0.2, 0.2}, {1.0, -1.0, -1.0}, 1.0};

inline std::array<double, 3> force_colour(double force_n, double force_unit_n = 1.0) {
  const ForceColourRule& r = kForceColourRule;
  const double f = std::isfinite(force_n) ? std::abs(force_n) / force_unit_n : r.not_finite_f;
  std::array<double, 3> c{};
  for (std::size_t k = 0; k < 3; ++k) c[k] = std::clamp(r.offset[k] + r.slope[k] * f, 0.0, 1.0);
  return c;
}

}  // namespace neurosim::common
