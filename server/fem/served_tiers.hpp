// Which elasticity tiers scenes and programs may run. COROTATIONAL stays a law of the FEM library
// (elastic_law.hpp: tests and comparisons) but is not served: scenes (effects.tier) and the
// programs' --tier refuse it with kCorotationalWithdrawn. Header-only, as tier.hpp.
#pragma once

#include "server/fem/tier.hpp"

namespace neurosim::fem {

inline constexpr const char* kCorotationalWithdrawn =
    "the COROTATIONAL tier is withdrawn: on the brain scene it settled at 0 N with the tool 10 mm "
    "deep and its force kept moving by 44 % at 20 mm (docs/accuracy.md); use LINEAR (fastest) or "
    "NONLINEAR (large deformation, CalculiX's neo-Hooke)";

inline bool tier_served(Tier tier) { return tier != Tier::kCorotational; }

}  // namespace neurosim::fem
