#include "server/fem/element_barrier.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <algorithm>
#include <stdexcept>

namespace neurosim::fem {

namespace {

using Mat3 = Eigen::Matrix3d;

Mat3 cofactor(const Mat3& f) {  // det(F) F^-T, a polynomial of F
  Mat3 c;
  c.col(0) = f.col(1).cross(f.col(2));
  c.col(1) = f.col(2).cross(f.col(0));
  c.col(2) = f.col(0).cross(f.col(1));
  return c;
}

struct Gaps {
  double j{0.0};  // max(0, J_min - J)
  double i{0.0};  // max(0, (I1 - I1_max) / 3)
};

Gaps gaps(const Mat3& f) {
  Gaps g;
  g.j = std::max(0.0, ElementBarrier::kMinJ - f.determinant());
  g.i = std::max(0.0, (f.squaredNorm() - ElementBarrier::kMaxI1) / 3.0);
  return g;
}

}  // namespace

ElementBarrier ElementBarrier::of(const LawConstants& law) {
  if (!(law.mu_pa > 0.0)) {
    throw std::invalid_argument("ElementBarrier: the shear modulus must be positive");
  }
  return ElementBarrier{kStiffnessShare * law.mu_pa};
}

bool ElementBarrier::active(const Mat3& h) const {
  const Gaps g = gaps(Mat3::Identity() + h);
  return g.j > 0.0 || g.i > 0.0;
}

double ElementBarrier::energy_density(const Mat3& h) const {
  const Gaps g = gaps(Mat3::Identity() + h);
  return stiffness_pa * (g.j * g.j * g.j + g.i * g.i * g.i);
}

Mat3 ElementBarrier::stress(const Mat3& h) const {
  const Mat3 f = Mat3::Identity() + h;
  const Gaps g = gaps(f);
  // d(J_min - J)^3 = -3 g_j^2 cof F; d((I1 - I1_max) / 3)^3 = 3 g_i^2 (2 F / 3).
  return stiffness_pa * (-3.0 * g.j * g.j * cofactor(f) + 2.0 * g.i * g.i * f);
}

void ElementBarrier::add_tangent(const Mat3& h, StressTangent& dp_df) const {
  const Mat3 f = Mat3::Identity() + h;
  const Gaps g = gaps(f);
  if (g.j > 0.0) {
    // 6 g_j cof (x) cof - 3 g_j^2 d2J, d cof(F)[dF] = cof(F + dF) - cof F - cof dF.
    const Mat3 cf = cofactor(f);
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> c(cf.data());
    dp_df.noalias() += stiffness_pa * 6.0 * g.j * (c * c.transpose());
    for (int l = 0; l < 3; ++l) {
      for (int k = 0; k < 3; ++k) {
        Mat3 df = Mat3::Zero();
        df(k, l) = 1.0;
        const Mat3 d = cofactor(f + df) - cf - cofactor(df);
        dp_df.col(k + 3 * l) -= stiffness_pa * 3.0 * g.j * g.j *
                                Eigen::Map<const Eigen::Matrix<double, 9, 1>>(d.data());
      }
    }
  }
  if (g.i > 0.0) {
    // d(2 g_i^2 F) = 4 g_i (2 F / 3 : dF) F + 2 g_i^2 dF.
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> v(f.data());
    dp_df.noalias() += stiffness_pa * (8.0 / 3.0) * g.i * (v * v.transpose());
    dp_df.diagonal().array() += stiffness_pa * 2.0 * g.i * g.i;
  }
}

}  // namespace neurosim::fem
