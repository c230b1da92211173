// Prescribed displacements by component: a set of nodes whose chosen components (a subset of
// x, y, z) take given values while the other components stay free unknowns, as CalculiX's
// *BOUNDARY with NSET,3,3 (only uz prescribed).
#pragma once

#include <Eigen/Core>

#include <array>
#include <string>
#include <vector>

namespace neurosim::fem {

using Components = std::array<bool, 3>;  // prescribed or not, for x, y, z
inline constexpr Components kAllComponents{true, true, true};

// Parses a non-empty subset of "xyz" in any order ("z", "xy", "zyx"). Throws
// std::invalid_argument for an empty string, a character other than x, y, z (named in the
// message) or a component given twice.
Components parse_components(const std::string& spec);

// "xyz", "z", "xz", ...; "" when no component is set.
std::string components_string(const Components& components);

// One prescribed displacement: every node in `nodes` takes displacement_m in the components
// marked in `components`; its other components are free. Values of unmarked components are
// ignored.
struct PrescribedDofs {
  std::vector<int> nodes;
  Eigen::Vector3d displacement_m{Eigen::Vector3d::Zero()};  // unit m
  Components components{kAllComponents};
};

// Constrained degrees of freedom of a list of PrescribedDofs, merged and validated.
struct PrescribedDofList {
  std::vector<int> dofs;     // 3 * node + axis, ascending, unique
  Eigen::VectorXd values_m;  // one per dof, unit m
  std::vector<int> nodes;    // nodes with at least one prescribed component, ascending
};

// Validates and merges definitions. Refused (std::invalid_argument, the message names the
// definition as "prescribed[k]", the node and the axis): a definition with no node or no
// component, a node out of [0, num_nodes), a non-finite value in a prescribed component, a node
// that is in fixed_nodes (u = 0 in x, y, z there), and a component of a node prescribed twice
// (in one definition or two) with different values. The same value given twice is merged.
PrescribedDofList expand_prescribed(const std::vector<PrescribedDofs>& prescribed, int num_nodes,
                                    const std::vector<int>& fixed_nodes = {});

}  // namespace neurosim::fem
