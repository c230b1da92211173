#include "server/fem/material.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

namespace {
std::string label(const Material& m) {
  return "material '" + (m.name.empty() ? std::string("<unnamed>") : m.name) + "'";
}
}  // namespace

void Material::validate() const {
  if (!std::isfinite(youngs_modulus_pa) || youngs_modulus_pa <= 0.0) {
    throw std::invalid_argument(label(*this) + ": Young's modulus must be finite and > 0 Pa, got " +
                                std::to_string(youngs_modulus_pa));
  }
  // nu = 0.5 is incompressible: lambda is infinite and the displacement formulation locks.
  if (!std::isfinite(poisson_ratio) || poisson_ratio <= -1.0 || poisson_ratio >= 0.5) {
    throw std::invalid_argument(label(*this) +
                                ": Poisson's ratio must be finite and in (-1, 0.5), got " +
                                std::to_string(poisson_ratio));
  }
  viscoelastic.validate(label(*this) + ": viscoelastic");
}

double Material::lame_lambda_pa() const {
  return youngs_modulus_pa * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio));
}

double Material::shear_modulus_pa() const {
  return youngs_modulus_pa / (2.0 * (1.0 + poisson_ratio));
}

Eigen::Matrix<double, 6, 6> elasticity_matrix(const Material& material) {
  material.validate();
  const double lambda = material.lame_lambda_pa();
  const double mu = material.shear_modulus_pa();
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
  d.topLeftCorner<3, 3>().setConstant(lambda);
  for (int i = 0; i < 3; ++i) {
    d(i, i) = lambda + 2.0 * mu;
    d(3 + i, 3 + i) = mu;
  }
  return d;
}

MaterialMap MaterialMap::uniform(Material material) {
  MaterialMap map;
  map.materials.push_back(std::move(material));
  return map;
}

MaterialMap MaterialMap::per_tet(std::vector<Material> materials, std::vector<int> tet_material) {
  MaterialMap map;
  map.materials = std::move(materials);
  map.tet_material = std::move(tet_material);
  return map;
}

void MaterialMap::validate(std::size_t num_tets) const {
  if (materials.empty()) {
    throw std::invalid_argument("MaterialMap: no material given");
  }
  for (const Material& m : materials) {
    m.validate();
    if (m.element != materials.front().element) {
      throw std::invalid_argument("MaterialMap: " + label(m) + " asks for element '" +
                                  element_name(m.element) + "' but " + label(materials.front()) +
                                  " for '" + element_name(materials.front().element) +
                                  "': one mesh has one element");
    }
  }
  if (tet_material.empty()) {
    return;
  }
  if (tet_material.size() != num_tets) {
    throw std::invalid_argument("MaterialMap: " + std::to_string(tet_material.size()) +
                                " per-tetrahedron material ids for a mesh of " +
                                std::to_string(num_tets) + " tetrahedra");
  }
  for (std::size_t t = 0; t < num_tets; ++t) {
    const int id = tet_material[t];
    if (id < 0 || static_cast<std::size_t>(id) >= materials.size()) {
      throw std::invalid_argument("MaterialMap: tetrahedron " + std::to_string(t) +
                                  " has material id " + std::to_string(id) + ", but only " +
                                  std::to_string(materials.size()) + " materials exist");
    }
  }
}

}  // namespace neurosim::fem
