// Rotation-variant SVD and polar rotation of a 3x3 deformation gradient, stable for flat and
// inverted elements: F = U diag(sigma) V^T with U, V proper rotations (det +1); an inverted F
// (det F < 0) gets its smallest singular value negated instead of a reflection in U or V
// (Irving, Teran, Fedkiw 2004; SOFA's TetrahedronFEMForceField method "svd").
#pragma once

#include <Eigen/Core>

namespace neurosim::fem {

struct RotationVariantSvd {
  Eigen::Matrix3d u;      // rotation, det +1
  Eigen::Vector3d sigma;  // sigma_0 >= sigma_1 >= |sigma_2|; sigma_2 < 0 iff det F < 0
  Eigen::Matrix3d v;      // rotation, det +1
};

// Throws std::invalid_argument if F has a non-finite entry.
RotationVariantSvd rotation_variant_svd(const Eigen::Matrix3d& f);

// R = U V^T of the rotation-variant SVD: the rotation of the polar decomposition F = R S with S
// symmetric (S may have one negative eigenvalue for an inverted F). Defined for flat F (rank 2,
// the missing direction completed by the right-hand rule) and for F = 0 (identity).
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& f);

}  // namespace neurosim::fem
