#include "server/fem/polar_decomposition.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>

#include <stdexcept>

namespace neurosim::fem {

RotationVariantSvd rotation_variant_svd(const Eigen::Matrix3d& f) {
  if (!f.allFinite()) {
    throw std::invalid_argument("rotation_variant_svd: non-finite deformation gradient");
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  RotationVariantSvd r{svd.matrixU(), svd.singularValues(), svd.matrixV()};
  // JacobiSVD returns orthogonal U, V (det +-1) and sigma >= 0, sorted descending. Make both
  // proper rotations by flipping their last column; each flip negates sigma_2 once.
  if (r.u.determinant() < 0.0) {
    r.u.col(2) = -r.u.col(2);
    r.sigma(2) = -r.sigma(2);
  }
  if (r.v.determinant() < 0.0) {
    r.v.col(2) = -r.v.col(2);
    r.sigma(2) = -r.sigma(2);
  }
  return r;
}

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& f) {
  const RotationVariantSvd s = rotation_variant_svd(f);
  return s.u * s.v.transpose();
}

}  // namespace neurosim::fem
