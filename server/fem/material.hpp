// Isotropic linear elastic material (Young's modulus, Poisson's ratio) and its Lamé parameters.
#pragma once

#include "server/fem/element.hpp"
#include "server/fem/viscoelastic.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace neurosim::fem {

struct Material {
  double youngs_modulus_pa{0.0};  // E, unit Pa
  double poisson_ratio{0.0};      // nu, dimensionless, in (-1, 0.5)
  std::string name;               // for messages ("brain", "artery")
  // The element formulation (element.hpp). The library's default is the constant-strain
  // tetrahedron; scenes default to kDefaultSceneElement.
  Element element{Element::kLinearTet};
  // The relaxation kernel (viscoelastic.hpp); no terms: elastic. E and nu are instantaneous.
  Viscoelastic viscoelastic{};

  // Throws std::invalid_argument naming the material if E <= 0, nu outside (-1, 0.5)
  // or either is non-finite.
  void validate() const;
  double lame_lambda_pa() const;    // lambda = E nu / ((1 + nu)(1 - 2 nu)), unit Pa
  double shear_modulus_pa() const;  // mu = G = E / (2 (1 + nu)), unit Pa
};

// 6x6 isotropic elasticity matrix D (Pa) in Voigt order xx, yy, zz, xy, yz, zx with
// engineering shear strains (gamma_xy = 2 eps_xy).
Eigen::Matrix<double, 6, 6> elasticity_matrix(const Material& material);

// One material for a whole mesh, or one per tetrahedron (index into `materials`).
struct MaterialMap {
  std::vector<Material> materials;
  // Per tetrahedron: index into `materials`; empty means every tetrahedron uses materials[0].
  std::vector<int> tet_material;

  static MaterialMap uniform(Material material);
  static MaterialMap per_tet(std::vector<Material> materials, std::vector<int> tet_material);

  // Validates every material and, for per-tet maps, the size and the indices (names the tet);
  // every material must name the same element (the nodal terms of anp-tet span materials).
  void validate(std::size_t num_tets) const;
  // The mesh's element (materials[0]'s; validate() checks that all agree).
  Element element() const { return materials.empty() ? Element::kLinearTet : materials.front().element; }
  const Material& of_tet(std::size_t tet) const {
    return tet_material.empty() ? materials.front() : materials[tet_material[tet]];
  }
};

}  // namespace neurosim::fem
