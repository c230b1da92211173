// Plausible ranges of scene values (SI units): the one table validate_scene checks against and
// what anything else that must agree with the validator reads (the scene fuzz target's
// properties, documentation). Beyond them a value is a typo or hostile input that would make
// the server sleep for years between steps, allocate gigabytes per status period, or "solve" to
// displacements of astronomical size; validate_scene refuses it naming the field and the range.
// Generous for a surgical scene: the patient model uses E of kPa to MPa, tools of mm, forces of
// N, rates of 1 Hz to 1 kHz.
#pragma once

#include <cmath>

namespace neurosim::scene::ranges {

// [lo, hi], both included. zero_is_default: 0 (unset) means "the default" and is accepted though
// outside the range.
struct Range {
  double lo, hi;
  const char* unit;
  bool zero_is_default;
  bool contains(double v) const {
    return (zero_is_default && v == 0.0) || (std::isfinite(v) && v >= lo && v <= hi);
  }
};

inline constexpr Range kYoungsModulus{1e-3, 1e12, "Pa", false};  // below any gel to above steel
inline constexpr Range kFileUnit{1e-9, 1e3, "m", false};
inline constexpr Range kImageFileUnit{1e-9, 1e3, "m", true};
inline constexpr Range kCoordinate{-10.0, 10.0, "m", false};  // generated shapes, any component
inline constexpr Range kLength{0.0, 10.0, "m", false};        // generated sizes
inline constexpr Range kToolRadius{0.0, 0.1, "m", false};     // tip (also > 0) and shaft
inline constexpr Range kToolLength{0.0, 1.0, "m", false};
inline constexpr Range kToolSpeed{0.0, 100.0, "m/s", true};
inline constexpr Range kForce{-1e6, 1e6, "N", false};         // any component of a load
inline constexpr Range kDisplacement{-1.0, 1.0, "m", false};  // any component of a prescription
inline constexpr Range kStepRate{10.0, 1e5, "Hz", true};  // the server refuses above 1 MHz anyway
inline constexpr Range kViewerRate{0.1, 1e3, "Hz", true};
// With the step rate, bounds the steps per status period (<= 1e6) the server keeps times for.
inline constexpr Range kStatusRate{0.1, 100.0, "Hz", true};
inline constexpr Range kScale{1e-3, 1e3, "", true};  // haptic force and workspace scales
inline constexpr Range kMaxForce{0.0, 100.0, "N", true};
inline constexpr Range kOpeningRadius{0.0, 0.1, "m", false};      // a craniotomy of up to 20 cm
inline constexpr Range kOpeningHalfLength{0.0, 0.2, "m", false};  // through a head and beyond
// Far above what a 1 kHz model can step; about mesh::MeshingOptions::max_tetrahedra (2e6) at
// the mesher's ~6 tetrahedra per vertex. 0: use cell_size_m.
inline constexpr int kMaxGeneratedVertices = 300'000;
inline constexpr int kMaxStations = 64;  // SimStatus.stations holds at most 64; 0: the default

}  // namespace neurosim::scene::ranges
