#include "server/fem/elastic_forces.hpp"

#include "server/fem/tet_element.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

namespace {

// Largest |principal Green-Lagrange strain|, E = (H + H^T + H^T H) / 2.
double green_strain_magnitude(const Eigen::Matrix3d& h) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(
      0.5 * (h + h.transpose() + h.transpose() * h), Eigen::EigenvaluesOnly);
  const Eigen::Vector3d e = eig.eigenvalues();
  return std::max(std::abs(e(0)), std::abs(e(2)));
}

void note(ElasticForcesReport* report, const Eigen::Matrix3d& h, const LawEvaluation& eval) {
  if (!report) return;
  if (eval.clamped) ++report->clamped_elements;
  if ((Eigen::Matrix3d::Identity() + h).determinant() <= 0.0) ++report->inverted_elements;
  report->max_strain = std::max(report->max_strain, green_strain_magnitude(h));
}

}  // namespace

ElasticForces::ElasticForces(const mesh::TetMesh& mesh, const MaterialMap& materials, Tier tier)
    : tier_(tier),
      num_nodes_(static_cast<int>(mesh.num_vertices())),
      tets_(mesh.tets()),
      assembler_(mesh) {
  materials.validate(mesh.num_tets());
  for (const Material& m : materials.materials) {
    laws_.push_back(LawConstants::of(m));
  }
  const auto& x = mesh.vertices();
  gradients_.resize(tets_.size());
  volume_m3_.resize(tets_.size());
  law_index_.resize(tets_.size());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const auto& t = tets_[e];
    const TetGeometry g =
        tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e));
    gradients_[e] = g.gradients;
    volume_m3_[e] = g.volume_m3;
    total_volume_m3_ += g.volume_m3;
    law_index_[e] = materials.tet_material.empty() ? 0 : materials.tet_material[e];
  }
}

void ElasticForces::check_size(const Eigen::VectorXd& u_m, const char* what) const {
  if (u_m.size() != num_dofs()) {
    throw std::invalid_argument(std::string("ElasticForces::") + what + ": displacement has " +
                                std::to_string(u_m.size()) + " entries, expected " +
                                std::to_string(num_dofs()));
  }
}

Eigen::Matrix3d ElasticForces::displacement_gradient(std::size_t tet,
                                                     const Eigen::VectorXd& u_m) const {
  Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
  const auto& t = tets_[tet];
  for (int a = 0; a < 4; ++a) {
    f.noalias() += u_m.segment<3>(3 * t[a]) * gradients_[tet].row(a);
  }
  return f;
}

double ElasticForces::energy(const Eigen::VectorXd& u_m, ElasticForcesReport* report) const {
  check_size(u_m, "energy");
  double e_total = 0.0;
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const Eigen::Matrix3d f = displacement_gradient(e, u_m);
    LawEvaluation eval;
    e_total += volume_m3_[e] * energy_density(tier_, laws_[law_index_[e]], f, &eval);
    note(report, f, eval);
  }
  return e_total;
}

void ElasticForces::internal_force(const Eigen::VectorXd& u_m, Eigen::VectorXd& f_n,
                                   ElasticForcesReport* report) const {
  check_size(u_m, "internal_force");
  f_n.setZero(num_dofs());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const Eigen::Matrix3d f = displacement_gradient(e, u_m);
    LawEvaluation eval;
    const Eigen::Matrix3d p = first_piola(tier_, laws_[law_index_[e]], f, &eval);
    note(report, f, eval);
    const auto& t = tets_[e];
    for (int a = 0; a < 4; ++a) {
      f_n.segment<3>(3 * t[a]).noalias() += volume_m3_[e] * (p * gradients_[e].row(a).transpose());
    }
  }
}

void ElasticForces::tangent(const Eigen::VectorXd& u_m, bool project_psd, SparseMatrix& k,
                            ElasticForcesReport* report) const {
  check_size(u_m, "tangent");
  const SparseMatrix& pattern = assembler_.pattern();
  if (k.rows() != pattern.rows() || k.nonZeros() != pattern.nonZeros() || !k.isCompressed()) {
    k = pattern;
  }
  double* values = k.valuePtr();
  std::fill_n(values, k.nonZeros(), 0.0);
  StressTangent c;
  Eigen::Matrix<double, 9, 12> b;
  Eigen::Matrix<double, 12, 12> k_e;
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const Eigen::Matrix3d f = displacement_gradient(e, u_m);
    LawEvaluation eval;
    stress_tangent(tier_, laws_[law_index_[e]], f, project_psd, c, &eval);
    note(report, f, eval);
    // vec(dF) = B du: dF(i, l) = sum_b du_b,i g_b,l at vec index i + 3 l.
    b.setZero();
    for (int a = 0; a < 4; ++a) {
      for (int l = 0; l < 3; ++l) {
        for (int i = 0; i < 3; ++i) {
          b(i + 3 * l, 3 * a + i) = gradients_[e](a, l);
        }
      }
    }
    k_e.noalias() = volume_m3_[e] * (b.transpose() * c * b);
    assembler_.add_element(e, k_e, values);
  }
}

}  // namespace neurosim::fem
