// The elasticity tiers a scene can ask for (effects.tier) and the physics implements
// (elastic_law.hpp). Header-only: the scene settings, which haptic stations read, name a tier
// without linking the FEM library.
#pragma once

#include <algorithm>
#include <cctype>
#include <optional>
#include <string>
#include <string_view>

namespace neurosim::fem {

enum class Tier { kLinear, kCorotational, kNonlinear };

// "LINEAR", "COROTATIONAL", "NONLINEAR" (the scene's spelling).
inline const char* tier_name(Tier tier) {
  switch (tier) {
    case Tier::kLinear: return "LINEAR";
    case Tier::kCorotational: return "COROTATIONAL";
    case Tier::kNonlinear: return "NONLINEAR";
  }
  return "UNKNOWN";
}

// Case-insensitive "linear" / "corotational" / "nonlinear"; nullopt for anything else.
inline std::optional<Tier> parse_tier(std::string_view name) {
  std::string lower(name);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  if (lower == "linear") return Tier::kLinear;
  if (lower == "corotational") return Tier::kCorotational;
  if (lower == "nonlinear") return Tier::kNonlinear;
  return std::nullopt;
}

}  // namespace neurosim::fem
