#include "server/fem/strain.hpp"

#include "server/fem/tet_element.hpp"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

StrainSummary max_principal_strain(const mesh::TetMesh& mesh, const Eigen::VectorXd& u_m) {
  const auto& x = mesh.vertices();
  if (u_m.size() != static_cast<Eigen::Index>(3 * x.size())) {
    throw std::invalid_argument("max_principal_strain: " + std::to_string(u_m.size()) +
                                " displacement values for " + std::to_string(x.size()) +
                                " vertices (3 each)");
  }
  for (Eigen::Index i = 0; i < u_m.size(); ++i) {
    if (!std::isfinite(u_m[i])) {
      throw std::invalid_argument("max_principal_strain: displacement of node " +
                                  std::to_string(i / 3) + " is not finite");
    }
  }
  StrainSummary out;
  const auto& tets = mesh.tets();
  for (std::size_t e = 0; e < tets.size(); ++e) {
    const auto& t = tets[e];
    const TetGeometry g = tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e));
    Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
    for (int a = 0; a < 4; ++a) f.noalias() += u_m.segment<3>(3 * t[a]) * g.gradients.row(a);
    if (f.determinant() <= 0.0) ++out.inverted;
    const Eigen::Matrix3d green = 0.5 * (f.transpose() * f - Eigen::Matrix3d::Identity());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(green, Eigen::EigenvaluesOnly);
    const double m = eig.eigenvalues().cwiseAbs().maxCoeff();
    if (m > out.max_strain || out.tet < 0) {
      out.max_strain = m;
      out.tet = static_cast<int>(e);
    }
  }
  return out;
}

}  // namespace neurosim::fem
