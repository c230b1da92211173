// The tetrahedral element formulations a scene can ask for (material.element). Header-only, as
// tier.hpp: the scene names an element without linking the FEM library.
//
//   linear-tet  the constant-strain 4-node tetrahedron (every term per element). Locks as
//               nu -> 0.5: one volume constraint per element, about six per node.
//   anp-tet     the average nodal pressure tetrahedron (Bonet & Burton 1998; Joldes, Wittek &
//               Miller 2009): the same 4 nodes and linear shape functions, the deviatoric energy
//               per element, the volumetric energy per node from the nodal volume change
//               (one constraint per node), so it does not lock (nodal_pressure.hpp).
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace neurosim::fem {

enum class Element { kLinearTet, kAnpTet };

// "linear-tet", "anp-tet" (the scene's spelling).
inline const char* element_name(Element element) {
  switch (element) {
    case Element::kLinearTet: return "linear-tet";
    case Element::kAnpTet: return "anp-tet";
  }
  return "unknown";
}

// The names parse_element accepts, for error messages.
inline const char* element_names() { return "anp-tet, linear-tet"; }

// The element of a scene that names none. Still linear-tet: with anp-tet the multirate worker's
// held NONLINEAR force on the brain settles 4 % away from the synchronous updates' answer
// (service_tier.BrainNonlinear, interaction_tier WorkerThreadReachesTheSynchronousAnswer), an
// open defect; scenes ask for anp-tet by name.
inline constexpr Element kDefaultSceneElement = Element::kLinearTet;

// Exact (case-sensitive) "linear-tet" / "anp-tet"; nullopt for anything else.
inline std::optional<Element> parse_element(std::string_view name) {
  if (name == "linear-tet") return Element::kLinearTet;
  if (name == "anp-tet") return Element::kAnpTet;
  return std::nullopt;
}

}  // namespace neurosim::fem
