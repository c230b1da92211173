// Richardson extrapolation of a quantity computed on three nested meshes, h halved each time
// (tet_split.hpp's 1 -> 8 splits): the converged (continuum) answer and the observed order.
// Used by press_refinement_bench and accuracy_bench for their patch presses' converged answer.
#pragma once

#include <cmath>
#include <string>

namespace neurosim::bench {

// A Richardson limit: the observed order and the extrapolated value (the caller's unit), or NaN
// and why.
struct Limit {
  double order{std::nan("")}, force_n{std::nan("")};
  std::string why;
};

// F(h) = F* + C h^p from the values on three nested meshes (h halved each time, f2 the finest):
// p = log2((f0 - f1) / (f1 - f2)), F* = f2 - (f1 - f2) / (2^p - 1). Refused when a value is
// missing, the differences vanish or change sign, or p < 0.3 (no asymptotic range).
inline Limit richardson(double f0, double f1, double f2) {
  Limit l;
  const double d01 = f0 - f1, d12 = f1 - f2;
  if (!std::isfinite(f0) || !std::isfinite(f1) || !std::isfinite(f2)) {
    l.why = "a mesh missing";
  } else if (d12 == 0.0 || d01 / d12 <= 0.0) {
    l.why = "the differences vanish or change sign";
  } else {
    l.order = std::log2(d01 / d12);
    if (l.order < 0.3) l.why = "order below 0.3";
    else l.force_n = f2 - d12 / (std::exp2(l.order) - 1.0);
  }
  return l;
}

// The converged answer from two elements' limits on the same nested meshes: C3D10's when it
// has one (it ran on all three levels with an asymptotic range), else smoothed-tet's (where both
// had one they met within 2 %); force_n NaN when neither has.
struct ConvergedAnswer {
  double force_n{std::nan("")};
  const char* by{"no limit"};
};
inline ConvergedAnswer converged_answer(const Limit& c3d10, const Limit& smoothed_tet) {
  if (std::isfinite(c3d10.force_n)) return {c3d10.force_n, "C3D10's limit"};
  if (std::isfinite(smoothed_tet.force_n)) return {smoothed_tet.force_n, "smoothed-tet's limit"};
  return {};
}

}  // namespace neurosim::bench
